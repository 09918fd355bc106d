/* The Python face of ase_bpm's compiled kernels: one shared library built
 * from every C file in this folder (setup.py), loaded by
 * ase_bpm/laws/compiled.py through ctypes.  This file only lets setuptools
 * build the library as an extension module and Python import it, and tells
 * which source text it was built from.
 */

#include <Python.h>

/* The digest of the sources this library was built from (setup.py). */
#ifndef ASE_BPM_SOURCE_DIGEST
#define ASE_BPM_SOURCE_DIGEST "unknown"
#endif
const char *kernels_source_digest(void) { return ASE_BPM_SOURCE_DIGEST; }

/* A module with no Python functions: the kernels are called through ctypes. */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels",
                                    "ase_bpm's compiled kernels (called through ctypes).",
                                    -1, NULL};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
