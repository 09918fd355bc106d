"""An input deck's text: its commands by line, continuation lines joined and
comments removed as LAMMPS does (:func:`read_deck`), in a :class:`Deck` that
marks each command as understood when a reader takes it and refuses, by line,
what ase_bpm cannot carry out (the table is :mod:`.lammps_commands`).
"""

from __future__ import annotations

import os
import shlex
from contextlib import contextmanager
from dataclasses import dataclass, field

from .lammps_commands import IGNORED, WRITTEN_BY, WRITTEN_OUTPUT, kind, refusal
from .lammps_data import _is_number


@dataclass
class Deck:
    """An input deck's commands (``(line number, words)``, continuation lines
    joined and comments removed as LAMMPS does), each marked as understood
    when a reader takes it."""

    path: str
    commands: list
    used: set = field(default_factory=set)
    written_by_ase_bpm: bool = False  # (its first line is write_lammps's WRITTEN_BY)

    def take(self, name: str, style: str | None = None) -> list:
        """``(line number, words after the command name)`` of the commands
        ``name`` (with ``style`` as their third argument, for fixes), marked
        as understood."""
        found = []
        for k, (number, words) in enumerate(self.commands):
            if words[0] == name and (style is None or words[3:4] == [style]):
                self.used.add(k)
                found.append((number, words[1:]))
        return found

    def last(self, name: str, default=None):
        """The arguments of the last command ``name`` (``default`` if none)."""
        found = self.take(name)
        return found[-1][1] if found else default

    def refuse(self, number: int, words, wanted: str):
        """A ValueError naming the line and what read_lammps reads there."""
        return ValueError(f"{self.path} line {number}: {' '.join(words)!r}: read_lammps "
                          f"reads {wanted}")

    @contextmanager
    def reading(self, number: int, words, wanted: str):
        """Turn a failure to read a command's arguments (a '*' range, a
        variable, a word missing) into :meth:`refuse`."""
        try:
            yield
        except (IndexError, ValueError, KeyError) as exc:
            if str(exc).startswith(self.path):
                raise
            raise self.refuse(number, words, wanted) from None

    def first_run(self) -> int:
        """The index of the first ``run`` of more than 0 steps (the number of
        commands if none): the scene read is the one that run starts from."""
        return next((k for k, (_, w) in enumerate(self.commands)
                     if w[0] == "run" and w[1:2] != ["0"]), len(self.commands))

    def up_to(self, end: int) -> "Deck":
        """The deck of the commands before index ``end``, none taken yet."""
        return Deck(self.path, self.commands[:end],
                    written_by_ase_bpm=self.written_by_ase_bpm)

    def refuse_refused(self) -> None:
        """Refuse, by line, the first command that changes the physics in a
        way ase_bpm does not (:func:`.lammps_commands.refusal`), before
        anything is read or run."""
        for number, words in self.commands:
            if kind(words) is None:
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r}: "
                                 f"{refusal(words)}")
            if (kind(words)[0] != IGNORED and any("$" in word for word in words)
                    and not (words[0] == "change_box" and _box_change(words[1:]))):
                # (write_lammps's change_box keeps a box face with LAMMPS's $(zhi))
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r}: '$' "
                                 "puts a variable's value into the line, which read_lammps "
                                 "does not do: write the value (or v_<name> where the "
                                 "command takes a variable)")
            if words[0] == "run" and not (words[1:2] and words[1].isdigit()):
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r}: "
                                 "read_lammps reads 'run N' with N a number of steps")

    def refuse_the_rest(self, end: int) -> list:
        """Every command before index ``end`` (the first run) not taken must
        be ignored (no effect on ase_bpm's physics) or a run; the commands
        after it are :func:`.lammps_stages.later_stages`' to check.  Returns
        the ignored lines of the whole deck, ``(number, words)``."""
        ignored = []
        for k, (number, words) in enumerate(self.commands):
            if k in self.used or words[0] == "run":
                continue
            if kind(words)[0] != IGNORED:
                if k > end:
                    continue
                raise ValueError(f"{self.path} line {number}: {' '.join(words)!r} has no "
                                 "ase_bpm counterpart: read_lammps reads the commands "
                                 "write_lammps writes and those docs/lammps.md lists")
            if not (self.written_by_ase_bpm and words[0] in WRITTEN_OUTPUT):
                ignored.append((number, words))
        return ignored


def read_deck(path: str | os.PathLike) -> Deck:
    """The commands of an input deck.  As LAMMPS: a line ending in ``&`` goes
    on on the next one (a comment ending in ``&`` too), then a ``#`` outside
    quotes starts a comment."""
    commands, pending, start = [], "", 0
    with open(path) as fh:
        lines = fh.read().splitlines()
    for number, raw in enumerate(lines, start=1):
        if not pending:
            start = number
        raw = raw.rstrip()
        if raw.endswith("&"):
            pending += raw[:-1] + " "
            continue
        text, pending = _strip_comment(pending + raw), ""
        words = shlex.split(text)
        if words:
            commands.append((start, words))
    if pending:
        raise ValueError(f"{path} line {start}: the last command ends in '&' with no line "
                         "after it")
    return Deck(str(path), commands,
                written_by_ase_bpm=bool(lines) and lines[0].startswith(WRITTEN_BY))


def _strip_comment(text: str) -> str:
    """The line without a comment outside quotes."""
    quote = None
    for k, char in enumerate(text):
        if quote:
            quote = None if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char == "#":
            return text[:k]
    return text


def _box_change(args):
    """``(bounds, faces)`` of ``change_box all <axis> final <lo> <hi> ...
    [boundary <x> <y> <z>] units box`` (the form write_lammps writes for
    :class:`LostAtoms`: ``bounds`` maps an axis index to ``(lo, hi)``, a
    bound None where it is ``$(<axis>lo)`` or ``$(<axis>hi)``, the box's
    own; ``faces`` is None without ``boundary``), or None for another form."""
    if args[:1] != ["all"] or args[-2:] != ["units", "box"]:
        return None
    bounds, faces, words = {}, None, args[1:-2]
    while words:
        axis = words[0]
        if axis in ("x", "y", "z") and words[1:2] == ["final"] and len(words) >= 4 \
                and all(_is_number(w) or w == f"$({axis}{side})"
                        for w, side in zip(words[2:4], ("lo", "hi"))):
            bounds["xyz".index(axis)] = tuple(float(w) if _is_number(w) else None
                                              for w in words[2:4])
            words = words[4:]
        elif words[0] == "boundary" and len(words) >= 4:
            faces, words = words[1:4], words[4:]
        else:
            return None
    return bounds, faces
