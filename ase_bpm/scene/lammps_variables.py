"""LAMMPS equal-style variables, evaluated as LAMMPS evaluates them during a run.

A deck moves an indenter with ``variable y equal "v_y0 + step*dt*v_vy"``
(``examples/peri``) or with ``elapsed``.  LAMMPS evaluates such a formula
whenever a fix reads it, at the step under way, with these words:

* ``step``: the timestep counter, which runs on from run to run;
* ``elapsed`` (and ``elaplong``, the same for a plain ``run N``): the steps
  since the start of the current run;
* ``dt``: the current timestep, so ``step*dt`` jumps when the timestep
  changes between runs, while ``time`` (the time at the last timestep change
  plus the steps since then times ``dt``) runs on smoothly;
* ``PI``, numbers and ``v_<name>`` (another equal-style variable).

Within one run each of these is a linear function of ``step``, so a formula
of them with ``+ - * / ^`` and parentheses is too, as long as no two
step-dependent parts multiply.  :meth:`Variables.linear` gives that function,
``value = constant + per_step * step``, for the run under way
(:class:`RunClock`); anything else (a function such as ``sqrt()``, another
thermo keyword, a formula not linear in the step) is refused, naming the
variable, its line and the part ase_bpm cannot evaluate.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

#: the thermo keywords a formula may use, and what each is during a run
CLOCK_WORDS = ("step", "elapsed", "elaplong", "dt", "time")
#: LAMMPS' named constants ase_bpm evaluates
CONSTANTS = {"PI": math.pi}
#: what a formula may hold, for the refusals
EVALUATED = ("numbers, v_<name> of another equal-style variable, step, elapsed, elaplong, "
             "dt, time and PI, joined by + - * / ^ and parentheses, linear in the step")
TOKEN = re.compile(r"\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
                   r"|(?P<name>[A-Za-z_][A-Za-z_0-9]*(?:\[\d+\])?)(?P<call>\s*\()?"
                   r"|(?P<symbol>[-+*/^()]))")


@dataclass(frozen=True)
class RunClock:
    """The run under way, as LAMMPS' clock words see it: ``first_step``, the
    step it started at; ``timestep`` (``dt``); ``time_at_first_step``, the
    time then (``time`` = it + (step - first_step) * dt)."""

    first_step: int = 0
    timestep: float = 1.0
    time_at_first_step: float = 0.0


@dataclass(frozen=True)
class Linear:
    """A value during one run: ``constant + per_step * step``."""

    constant: float
    per_step: float = 0.0

    def at(self, step: int) -> float:
        return self.constant + self.per_step * step

    def __add__(self, other: "Linear") -> "Linear":
        return Linear(self.constant + other.constant, self.per_step + other.per_step)

    def scaled(self, factor: float) -> "Linear":
        return Linear(self.constant * factor, self.per_step * factor)


class VariableError(ValueError):
    """A formula ase_bpm cannot evaluate as LAMMPS would."""


class Variables:
    """The equal-style variables a deck has defined so far (a name defined
    again replaces its formula, as in LAMMPS)."""

    def __init__(self, path: str = "deck"):
        self.path = path
        self.formulas = {}  # name -> (line number, formula)

    def define(self, number: int, words) -> None:
        """``variable <name> equal <formula>`` (``words`` after ``variable``)."""
        if len(words) != 3 or words[1] != "equal":
            raise VariableError(f"{self.path} line {number}: {' '.join(['variable', *words])!r}: "
                                "ase_bpm evaluates 'variable <name> equal \"<formula>\"' (one "
                                "quoted formula)")
        self.formulas[words[0]] = (number, words[2])

    def linear(self, name: str, clock: RunClock, _seen: tuple = ()) -> Linear:
        """The value of ``v_<name>`` during the run of ``clock``."""
        if name not in self.formulas:
            raise VariableError(f"{self.path}: v_{name} names no equal-style variable defined "
                                "before it is used")
        if name in _seen:
            raise VariableError(f"{self.path}: variable {name} refers to itself through "
                                f"{' -> '.join(_seen + (name,))}")
        number, formula = self.formulas[name]
        try:
            return _Parser(formula, lambda other: self.linear(other, clock, _seen + (name,)),
                           clock).formula()
        except VariableError as exc:
            if str(exc).startswith(self.path):
                raise
            raise VariableError(f"{self.path} line {number}: variable {name} = {formula!r}: "
                                f"{exc}; ase_bpm evaluates {EVALUATED}") from None

    def value(self, word: str, clock: RunClock) -> Linear:
        """A number or ``v_<name>`` as a fix argument takes it."""
        if word.startswith("v_"):
            return self.linear(word[2:], clock)
        return Linear(float(word))


def clock_word(word: str, clock: RunClock) -> Linear:
    """A thermo keyword of :data:`CLOCK_WORDS` during the run of ``clock``."""
    dt = clock.timestep
    if word == "step":
        return Linear(0.0, 1.0)
    if word in ("elapsed", "elaplong"):
        return Linear(-float(clock.first_step), 1.0)
    if word == "dt":
        return Linear(dt)
    return Linear(clock.time_at_first_step - clock.first_step * dt, dt)  # time


class _Parser:
    """A recursive-descent reading of one formula into a :class:`Linear`
    (LAMMPS' precedence, measured in the reference build: unary signs over
    ``^``, left to right, over ``* /`` over ``+ -``)."""

    def __init__(self, text: str, variable, clock: RunClock):
        self.tokens, self.k = self._tokens(text), 0
        self.variable, self.clock = variable, clock

    @staticmethod
    def _tokens(text: str) -> list:
        tokens, at = [], 0
        text = text.rstrip()
        while at < len(text):
            found = TOKEN.match(text, at)
            if found is None or found.end() == at:
                raise VariableError(f"{text[at:].strip()!r} is not part of a formula")
            if found.group("call"):
                raise VariableError(f"{found.group('name')}() is a function")
            kind = next(k for k in ("number", "name", "symbol") if found.group(k))
            tokens.append((kind, found.group(kind)))
            at = found.end()
        return tokens

    def _peek(self):
        return self.tokens[self.k] if self.k < len(self.tokens) else (None, None)

    def _take(self):
        token = self._peek()
        self.k += 1
        return token

    def formula(self) -> Linear:
        value = self._sum()
        if self.k != len(self.tokens):
            raise VariableError(f"{self._peek()[1]!r} where the formula should end")
        return value

    def _sum(self) -> Linear:
        value = self._product()
        while self._peek()[1] in ("+", "-"):
            sign = -1.0 if self._take()[1] == "-" else 1.0
            value = value + self._product().scaled(sign)
        return value

    def _product(self) -> Linear:
        value = self._power()
        while self._peek()[1] in ("*", "/"):
            operator, right = self._take()[1], self._power()
            if operator == "*":
                if value.per_step and right.per_step:
                    raise VariableError("a product of two step-dependent parts is not "
                                        "linear in the step")
                value = (value.scaled(right.constant) if not right.per_step
                         else right.scaled(value.constant))
            else:
                if right.per_step or right.constant == 0.0:
                    raise VariableError("a division by a step-dependent part or by zero")
                value = value.scaled(1.0 / right.constant)
        return value

    def _power(self) -> Linear:
        value = self._unary()
        while self._peek()[1] == "^":  # (left to right: 2^3^2 is 64)
            self._take()
            exponent = self._unary()
            if value.per_step or exponent.per_step:
                raise VariableError("a power of a step-dependent part is not linear in the "
                                    "step")
            value = Linear(value.constant ** exponent.constant)
        return value

    def _unary(self) -> Linear:  # (binds tighter than ^: -2^2 is 4)
        if self._peek()[1] in ("+", "-"):
            sign = -1.0 if self._take()[1] == "-" else 1.0
            return self._unary().scaled(sign)
        return self._atom()

    def _atom(self) -> Linear:
        kind, text = self._take()
        if kind == "number":
            return Linear(float(text))
        if text == "(":
            value = self._sum()
            if self._take()[1] != ")":
                raise VariableError("a '(' without its ')'")
            return value
        if kind == "name" and text.startswith("v_"):
            return self.variable(text[2:])
        if kind == "name" and text in CLOCK_WORDS:
            return clock_word(text, self.clock)
        if kind == "name" and text in CONSTANTS:
            return Linear(CONSTANTS[text])
        if kind == "name":
            raise VariableError(f"{text!r} is a thermo keyword, reference or name ase_bpm "
                                "does not evaluate")
        raise VariableError(f"{text!r} where a number, name or '(' should be" if text
                            else "the formula ends early")
