/* The Python face of ase_bpm's compiled kernels: one shared library built
 * from every C file in this folder (setup.py), loaded by
 * ase_bpm/laws/compiled.py through ctypes.  This file lets setuptools build
 * the library as an extension module and Python import it, tells which
 * source text it was built from, and hands the kernels' wrappers the
 * addresses of their arrays.
 */

#include <Python.h>
#include <stdint.h>

/* The digest of the sources this library was built from (setup.py). */
#ifndef ASE_BPM_SOURCE_DIGEST
#define ASE_BPM_SOURCE_DIGEST "unknown"
#endif
const char *kernels_source_digest(void) { return ASE_BPM_SOURCE_DIGEST; }

/* Whether the library was built with OpenMP (the _OPENMP date, else 0): the
 * kernels that take a thread count run serially without it (bonds.h). */
int64_t kernels_openmp(void)
{
#ifdef _OPENMP
    return _OPENMP;
#else
    return 0;
#endif
}

/* address(array): the address of a C-contiguous array's first byte, for
 * ctypes (None for None: NULL).  A buffer that is not C-contiguous raises
 * BufferError.  NumPy's own ndarray.ctypes.data builds an object each time
 * and costs ten times as much, which mattered with a dozen arrays per call
 * on small scenes. */
static PyObject *address(PyObject *self, PyObject *obj)
{
    (void)self;
    if (obj == Py_None)
        Py_RETURN_NONE;
    Py_buffer view;
    if (PyObject_GetBuffer(obj, &view, PyBUF_C_CONTIGUOUS) < 0)
        return NULL;
    void *start = view.buf;
    PyBuffer_Release(&view);
    return PyLong_FromVoidPtr(start);
}

static PyMethodDef methods[] = {
    {"address", address, METH_O, "The address of a C-contiguous array (None: None)."},
    {NULL, NULL, 0, NULL}};

/* The kernels themselves are called through ctypes. */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels",
                                    "ase_bpm's compiled kernels (called through ctypes).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
