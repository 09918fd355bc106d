/* The Python face of ase_bpm's compiled kernels: one shared library built
 * from every C file in this folder (setup.py), loaded by
 * ase_bpm/laws/compiled.py through ctypes.  This file lets setuptools build
 * the library as an extension module and Python import it, tells which
 * source text it was built from, hands the kernels' wrappers the
 * addresses of their arrays, and does the sums a step needs outside the
 * kernels (dot_sum, damping_work, all_finite, same_bytes,
 * largest_displacement_squared, the integrators' add_to and any_nonzero,
 * put_rows, the history put back on the atoms, pairs_in_order, a new
 * neighbour list's pairs put in order, and members, which of its pairs are
 * bonded) without NumPy's per-call cost and
 * temporaries.
 */

#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

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

/* The doubles of a C-contiguous buffer of float64 (writable too, with
 * flags PyBUF_WRITABLE), or 0 with no error set (not such a buffer: the
 * caller returns NotImplemented and the Python side takes NumPy's way). */
static int doubles_with(PyObject *obj, Py_buffer *view, int flags)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | flags) < 0) {
        PyErr_Clear();
        return 0;
    }
    const char *format = view->format;
    if (format && (*format == '<' || *format == '=' || *format == '@'))
        format++;
    if (view->itemsize != 8 || !format || format[0] != 'd' || format[1] != '\0') {
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

static int doubles_of(PyObject *obj, Py_buffer *view) { return doubles_with(obj, view, 0); }

/* Two objects as C-contiguous float64 buffers of one length (doubles_of),
 * or 0 with nothing held and no error set. */
static int two_doubles_of(PyObject *first, PyObject *second, Py_buffer *a, Py_buffer *b)
{
    if (!doubles_of(first, a))
        return 0;
    if (!doubles_of(second, b)) {
        PyBuffer_Release(a);
        return 0;
    }
    if (a->len != b->len) {
        PyBuffer_Release(a);
        PyBuffer_Release(b);
        return 0;
    }
    return 1;
}

/* The sum of f[k] * x[k] over n elements (x0 given: of f[k] * (x[k] -
 * x0[k]), the same number as over a displacement array, without it), in four
 * running sums added at the end. */
static double products_sum(const double *f, const double *x, const double *x0, Py_ssize_t n)
{
    Py_ssize_t k = 0;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    if (x0 == NULL) {
        for (; k + 4 <= n; k += 4) {
            s0 += f[k] * x[k];
            s1 += f[k + 1] * x[k + 1];
            s2 += f[k + 2] * x[k + 2];
            s3 += f[k + 3] * x[k + 3];
        }
        for (; k < n; k++)
            s0 += f[k] * x[k];
    } else {
        for (; k + 4 <= n; k += 4) {
            s0 += f[k] * (x[k] - x0[k]);
            s1 += f[k + 1] * (x[k + 1] - x0[k + 1]);
            s2 += f[k + 2] * (x[k + 2] - x0[k + 2]);
            s3 += f[k + 3] * (x[k + 3] - x0[k + 3]);
        }
        for (; k < n; k++)
            s0 += f[k] * (x[k] - x0[k]);
    }
    return (s0 + s1) + (s2 + s3);
}

/* dot_sum(a, b): the sum of a * b over every element of two C-contiguous
 * float64 arrays of one size (four running sums, added at the end), as a
 * float; NotImplemented for anything else.  NumPy's einsum spends 4 us a call
 * on its dispatch, and a step of a small scene makes half a dozen. */
static PyObject *dot_sum(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "dot_sum takes two arrays");
        return NULL;
    }
    Py_buffer a, b;
    if (!two_doubles_of(args[0], args[1], &a, &b))
        Py_RETURN_NOTIMPLEMENTED;
    double sum = products_sum(a.buf, b.buf, NULL, a.len / 8);
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    return PyFloat_FromDouble(sum);
}

/* damping_work(f, f_last, x, x0): the energy damping forces took over a
 * step, -(sum f . dx + sum f_last . dx) / 2 with dx = x - x0 (x0 None: x is
 * dx), each sum as dot_sum makes it (products_sum), in one call without
 * temporaries; f or f_last None adds nothing.  All given arrays C-contiguous
 * float64 of one size, else NotImplemented. */
static PyObject *damping_work(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "damping_work takes f, f_last, x, x0");
        return NULL;
    }
    Py_buffer views[4];
    const double *data[4] = {NULL, NULL, NULL, NULL};
    static const int order[4] = {2, 0, 1, 3}; /* x first: the others match its size */
    int held[4] = {0, 0, 0, 0}, ok = args[2] != Py_None;
    for (int o = 0; o < 4 && ok; o++) {
        int a = order[o];
        if (args[a] == Py_None)
            continue;
        ok = doubles_of(args[a], &views[a]);
        if (ok) {
            held[a] = 1;
            data[a] = views[a].buf;
            ok = views[a].len == views[2].len;
        }
    }
    double taken = 0.0;
    if (ok) {
        Py_ssize_t n = views[2].len / 8;
        double work = 0.0, work_last = 0.0;
        if (data[0] != NULL)
            work = products_sum(data[0], data[2], data[3], n);
        if (data[1] != NULL)
            work_last = products_sum(data[1], data[2], data[3], n);
        taken = 0.0 - 0.5 * (work + work_last); /* (as the Python: +0.0, not -0.0) */
    }
    for (int a = 0; a < 4; a++)
        if (held[a])
            PyBuffer_Release(&views[a]);
    if (!ok)
        Py_RETURN_NOTIMPLEMENTED;
    return PyFloat_FromDouble(taken);
}

/* all_finite(a): whether every element of a C-contiguous float64 array is
 * finite (x * 0 is 0 for finite x and NaN for inf or NaN: one pass that
 * vectorizes), as a bool; NotImplemented for anything else. */
static PyObject *all_finite(PyObject *self, PyObject *obj)
{
    (void)self;
    Py_buffer a;
    if (!doubles_of(obj, &a))
        Py_RETURN_NOTIMPLEMENTED;
    const double *x = a.buf;
    Py_ssize_t n = a.len / 8, k = 0;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    for (; k + 4 <= n; k += 4) {
        s0 += x[k] * 0.0;
        s1 += x[k + 1] * 0.0;
        s2 += x[k + 2] * 0.0;
        s3 += x[k + 3] * 0.0;
    }
    for (; k < n; k++)
        s0 += x[k] * 0.0;
    PyBuffer_Release(&a);
    return PyBool_FromLong((s0 + s1) + (s2 + s3) == 0.0);
}

/* largest_displacement_squared(x, x0, u): the largest |x_n - x0_n - u|^2 over
 * the rows of two C-contiguous n x 3 float64 arrays (u: three floats, or
 * None for zeros), as a float, in one pass without temporaries; the squares
 * are added as ase_bpm.core.neighbours.largest_square adds them (the same
 * value).  NotImplemented for other arrays.  A Verlet list asks it every
 * step (has some atom moved half the skin?). */
static PyObject *largest_displacement_squared(PyObject *self, PyObject *const *args,
                                              Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "largest_displacement_squared takes x, x0, u");
        return NULL;
    }
    double u[3] = {0.0, 0.0, 0.0};
    if (args[2] != Py_None) {
        Py_buffer d;
        if (!doubles_of(args[2], &d))
            Py_RETURN_NOTIMPLEMENTED;
        if (d.len != 3 * 8) {
            PyBuffer_Release(&d);
            Py_RETURN_NOTIMPLEMENTED;
        }
        for (int c = 0; c < 3; c++)
            u[c] = ((const double *)d.buf)[c];
        PyBuffer_Release(&d);
    }
    Py_buffer a, b;
    if (!two_doubles_of(args[0], args[1], &a, &b))
        Py_RETURN_NOTIMPLEMENTED;
    if (a.len % (3 * 8) != 0) {
        PyBuffer_Release(&a);
        PyBuffer_Release(&b);
        Py_RETURN_NOTIMPLEMENTED;
    }
    const double *x = a.buf, *x0 = b.buf;
    Py_ssize_t n = a.len / (3 * 8);
    double largest = 0.0;
    int nan = 0;
    for (Py_ssize_t k = 0; k < n; k++) {
        const double d0 = x[3 * k] - x0[3 * k] - u[0];
        const double d1 = x[3 * k + 1] - x0[3 * k + 1] - u[1];
        const double d2 = x[3 * k + 2] - x0[3 * k + 2] - u[2];
        const double square = d0 * d0 + d1 * d1 + d2 * d2;
        nan |= square != square;
        largest = square > largest ? square : largest;
    }
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    return PyFloat_FromDouble(nan ? NAN : largest);
}

/* same_bytes(a, b): whether two C-contiguous buffers hold the same bytes
 * (memcmp, no copies), as a bool; NotImplemented for buffers that are not
 * C-contiguous.  The caller compares shapes and types first. */
static PyObject *same_bytes(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "same_bytes takes two arrays");
        return NULL;
    }
    Py_buffer a, b;
    if (PyObject_GetBuffer(args[0], &a, PyBUF_C_CONTIGUOUS) < 0) {
        PyErr_Clear();
        Py_RETURN_NOTIMPLEMENTED;
    }
    if (PyObject_GetBuffer(args[1], &b, PyBUF_C_CONTIGUOUS) < 0) {
        PyErr_Clear();
        PyBuffer_Release(&a);
        Py_RETURN_NOTIMPLEMENTED;
    }
    const int same = a.len == b.len && (a.len == 0 || memcmp(a.buf, b.buf, a.len) == 0);
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    return PyBool_FromLong(same);
}

/* Whether two buffers have the same shape (NumPy broadcasts others: the
 * caller takes NumPy's way for them). */
static int same_shape(const Py_buffer *a, const Py_buffer *b)
{
    if (a->ndim != b->ndim)
        return 0;
    for (int k = 0; k < a->ndim; k++)
        if (a->shape[k] != b->shape[k])
            return 0;
    return 1;
}

/* Whether b's bytes overlap a's without being a's very elements (one pass
 * over a would then read values it has already changed, which NumPy's
 * temporaries do not). */
static int overlaps_shifted(const Py_buffer *a, const Py_buffer *b)
{
    const char *a0 = a->buf, *b0 = b->buf;
    return b0 != a0 && b0 < a0 + a->len && a0 < b0 + b->len;
}

/* add_to(a, s, b, c, divide): a += s * b, times c or divided by c (None:
 * neither), element by element in place, in one pass without temporaries;
 * the same arithmetic as NumPy's a += s * b * c or a += s * b / c (s * b
 * first).  a, b and c: C-contiguous float64 arrays of one shape, a writable,
 * b and c either a itself or apart from it:
 * returns None when done; NotImplemented for anything else, with nothing
 * changed (the caller takes NumPy's way).  The integrators' kicks, drifts and turns: a
 * step of a small scene makes five. */
static PyObject *add_to(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "add_to takes a, s, b, c, divide");
        return NULL;
    }
    const double s = PyFloat_AsDouble(args[1]);
    if (s == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        Py_RETURN_NOTIMPLEMENTED;
    }
    const int divide = PyObject_IsTrue(args[4]);
    if (divide < 0)
        return NULL;
    Py_buffer a, b, c;
    if (!doubles_with(args[0], &a, PyBUF_WRITABLE))
        Py_RETURN_NOTIMPLEMENTED;
    if (!doubles_of(args[2], &b)) {
        PyBuffer_Release(&a);
        Py_RETURN_NOTIMPLEMENTED;
    }
    const int scaled = args[3] != Py_None;
    if (scaled && !doubles_of(args[3], &c)) {
        PyBuffer_Release(&a);
        PyBuffer_Release(&b);
        Py_RETURN_NOTIMPLEMENTED;
    }
    if (!same_shape(&a, &b) || (scaled && !same_shape(&a, &c)) || overlaps_shifted(&a, &b)
        || (scaled && overlaps_shifted(&a, &c))) {
        if (scaled)
            PyBuffer_Release(&c);
        PyBuffer_Release(&a);
        PyBuffer_Release(&b);
        Py_RETURN_NOTIMPLEMENTED;
    }
    double *x = a.buf;
    const double *y = b.buf, *z = scaled ? c.buf : NULL;
    const Py_ssize_t n = a.len / 8;
    if (!scaled)
        for (Py_ssize_t k = 0; k < n; k++)
            x[k] += s * y[k];
    else if (divide)
        for (Py_ssize_t k = 0; k < n; k++)
            x[k] += s * y[k] / z[k];
    else
        for (Py_ssize_t k = 0; k < n; k++)
            x[k] += s * y[k] * z[k];
    if (scaled)
        PyBuffer_Release(&c);
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    Py_RETURN_NONE;
}

/* any_nonzero(a): whether some element of a C-contiguous float64 array is
 * not zero (NaN is not zero), stopping at the first; NotImplemented for
 * anything else. */
static PyObject *any_nonzero(PyObject *self, PyObject *obj)
{
    (void)self;
    Py_buffer a;
    if (!doubles_of(obj, &a))
        Py_RETURN_NOTIMPLEMENTED;
    const double *x = a.buf;
    const Py_ssize_t n = a.len / 8;
    Py_ssize_t k = 0;
    while (k < n && x[k] == 0.0)
        k++;
    PyBuffer_Release(&a);
    return PyBool_FromLong(k < n);
}

/* A C-contiguous one-dimensional buffer of int64 or int32 (view->itemsize
 * says which), or 0 with nothing held and no error set. */
static int indices_of(PyObject *obj, Py_buffer *view)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        return 0;
    }
    const char *format = view->format;
    if (format && (*format == '<' || *format == '=' || *format == '@'))
        format++;
    const int integer = format && format[1] == '\0'
                        && (view->itemsize == 8 ? format[0] == 'q' || format[0] == 'l'
                                                : view->itemsize == 4 && format[0] == 'i');
    if (!integer || view->ndim != 1) {
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

/* Entry k of an index buffer of `size` bytes an entry (indices_of). */
static inline int64_t index_at(const void *entries, Py_ssize_t size, Py_ssize_t k)
{
    return size == 8 ? ((const int64_t *)entries)[k] : ((const int32_t *)entries)[k];
}

/* put_rows(dst, src, at_b, slot_b, rows): dst[at_b[r], slot_b[r]] = src[r]
 * (dst[at_b[r]] = src[r] where slot_b is None) for every r of rows (None:
 * every row of src), a row being what follows the indexed axes of dst; dst
 * and src C-contiguous float64, at_b, slot_b and rows C-contiguous int64
 * or int32.
 * NotImplemented for anything else, or for an index NumPy would wrap or
 * refuse (the Python side then takes NumPy's way, with its errors); nothing
 * is written then.  One pass without NumPy's gathered temporaries: the
 * per-bond history put back on the atoms every step (ves, eps). */
static PyObject *put_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "put_rows takes dst, src, at_b, slot_b, rows");
        return NULL;
    }
    Py_buffer dst, src, held[3];
    int nheld = 0;
    PyObject *result = Py_NotImplemented;
    if (!doubles_with(args[0], &dst, PyBUF_WRITABLE))
        Py_RETURN_NOTIMPLEMENTED;
    if (!doubles_of(args[1], &src)) {
        PyBuffer_Release(&dst);
        Py_RETURN_NOTIMPLEMENTED;
    }
    const void *index[3] = {NULL, NULL, NULL}; /* at_b, slot_b, rows */
    Py_ssize_t length[3] = {0, 0, 0}, size[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
        if (args[2 + k] == Py_None)
            continue;
        if (!indices_of(args[2 + k], &held[nheld]))
            goto done;
        index[k] = held[nheld].buf;
        length[k] = held[nheld].shape[0];
        size[k] = held[nheld].itemsize;
        nheld++;
    }
    const int axes = index[1] ? 2 : 1;
    const Py_ssize_t n = length[0];
    if (!index[0] || dst.ndim < axes || (index[1] && length[1] != n) || src.ndim < 1
        || src.shape[0] != n || overlaps_shifted(&dst, &src) || dst.buf == src.buf)
        goto done;
    Py_ssize_t width = 1; /* doubles in a row of dst */
    for (int k = axes; k < dst.ndim; k++)
        width *= dst.shape[k];
    if (n * width * 8 != src.len)
        goto done;
    const Py_ssize_t first = dst.shape[0], second = axes == 2 ? dst.shape[1] : 1;
    const Py_ssize_t count = index[2] ? length[2] : n;
    for (Py_ssize_t k = 0; k < count; k++) { /* every index first: all or nothing */
        const int64_t r = index[2] ? index_at(index[2], size[2], k) : k;
        if (r < 0 || r >= n)
            goto done;
        const int64_t at = index_at(index[0], size[0], r);
        const int64_t slot = index[1] ? index_at(index[1], size[1], r) : 0;
        if (at < 0 || at >= first || slot < 0 || slot >= second)
            goto done;
    }
    double *to = dst.buf;
    const double *from = src.buf;
    for (Py_ssize_t k = 0; k < count; k++) {
        const int64_t r = index[2] ? index_at(index[2], size[2], k) : k;
        const int64_t row = index_at(index[0], size[0], r) * second
                            + (index[1] ? index_at(index[1], size[1], r) : 0);
        for (Py_ssize_t c = 0; c < width; c++) /* (a few numbers: no library call) */
            to[row * width + c] = from[r * width + c];
    }
    result = Py_None;
done:
    for (int k = 0; k < nheld; k++)
        PyBuffer_Release(&held[k]);
    PyBuffer_Release(&dst);
    PyBuffer_Release(&src);
    Py_INCREF(result);
    return result;
}

/* A C-contiguous one-dimensional buffer of one-byte entries (NumPy's bool),
 * or 0 with no error set. */
static int flags_of(PyObject *obj, Py_buffer *view)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        return 0;
    }
    if (view->itemsize != 1 || view->ndim != 1) {
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

/* Two index buffers and one-byte flags, args[0..2], into held[0..2]
 * (indices_of, flags_of): how many are held (3 when all are; the caller
 * releases those held either way). */
static int indices_indices_flags(PyObject *const *args, Py_buffer *held)
{
    if (!indices_of(args[0], &held[0]))
        return 0;
    if (!indices_of(args[1], &held[1]))
        return 1;
    return flags_of(args[2], &held[2]) ? 3 : 2;
}

/* The most pairs of one first atom pairs_in_order sorts (by insertion, a
 * cost that grows with their square); a list with more leaves the sort to
 * NumPy. */
#define MOST_PAIRS_OF_ONE_ATOM 256

/* pairs_in_order(i_p, j_p, keep_p, i_k, j_k, rows_k): the pairs keep_p of a
 * pair search's list (i_p in ascending order, as matscipy gives it; j_p in
 * any order within an i), written in order of (i, j) into i_k and j_k, and
 * where rows_k is not None, the place of each among the kept pairs (their
 * rows, in the order of the list, of what goes with them: image shifts).
 * Pairs with equal (i, j), listed through two periodic images, keep the
 * order of the list: the order of a stable sort of the key i * natoms + j
 * (ase_bpm.core.neighbours.in_pair_order), in one pass, each atom's pairs
 * sorted by insertion (matscipy lists a dozen or so an atom).
 * i_p and j_p are C-contiguous int32 or int64 of one length, keep_p
 * one-byte flags of that length, i_k, j_k and rows_k writable C-contiguous
 * int64 of the number of kept pairs.  NotImplemented for anything else, for
 * i_p not in ascending order among the kept pairs, or for more than
 * MOST_PAIRS_OF_ONE_ATOM pairs of one atom (the outputs are then not what
 * they should be: the Python side sorts with NumPy). */
static PyObject *pairs_in_order(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "pairs_in_order takes i_p, j_p, keep_p, i_k, j_k, "
                                          "rows_k");
        return NULL;
    }
    Py_buffer held[6];
    int nheld = 0;
    PyObject *result = Py_NotImplemented;
    if ((nheld = indices_indices_flags(args, held)) < 3)
        goto done;
    int64_t *out[3] = {NULL, NULL, NULL}; /* i_k, j_k, rows_k */
    Py_ssize_t count = -1;
    for (int k = 0; k < 3; k++) {
        if (args[3 + k] == Py_None && k == 2)
            continue;
        if (args[3 + k] == Py_None || !indices_of(args[3 + k], &held[nheld]))
            goto done;
        Py_buffer *view = &held[nheld++];
        if (view->itemsize != 8 || view->readonly || (count >= 0 && view->shape[0] != count))
            goto done;
        count = view->shape[0];
        out[k] = view->buf;
    }
    const Py_ssize_t n = held[0].shape[0];
    if (held[1].shape[0] != n || held[2].shape[0] != n)
        goto done;
    const void *i_p = held[0].buf, *j_p = held[1].buf;
    const Py_ssize_t size_i = held[0].itemsize, size_j = held[1].itemsize;
    const char *keep_p = held[2].buf;
    int64_t *restrict i_k = out[0], *restrict j_k = out[1], *restrict rows_k = out[2];
    Py_ssize_t written = 0, start = 0; /* start: where the pairs of atom i_k[written-1] begin */
    for (Py_ssize_t p = 0; p < n; p++) {
        if (!keep_p[p])
            continue;
        const int64_t i = index_at(i_p, size_i, p), j = index_at(j_p, size_j, p);
        if (written == count)
            goto done; /* more kept pairs than room */
        if (written > 0 && i != i_k[written - 1]) {
            if (i < i_k[written - 1])
                goto done; /* not in ascending order */
            start = written;
        }
        if (written - start >= MOST_PAIRS_OF_ONE_ATOM)
            goto done;
        Py_ssize_t at = written; /* after every pair of this atom with j_k <= j */
        while (at > start && j_k[at - 1] > j) {
            j_k[at] = j_k[at - 1];
            if (rows_k)
                rows_k[at] = rows_k[at - 1];
            at--;
        }
        i_k[written] = i;
        j_k[at] = j;
        if (rows_k)
            rows_k[at] = written;
        written++;
    }
    if (written == count)
        result = Py_None;
done:
    for (int k = 0; k < nheld; k++)
        PyBuffer_Release(&held[k]);
    Py_INCREF(result);
    return result;
}

/* Where key lies in the ascending entries set[lo..count): the first place
 * whose entry is not below it, searched forward from lo by doubling steps
 * and then halving (a few steps when keys come in ascending order, as a
 * merge, and a binary search's at worst). */
static Py_ssize_t place_from(const void *set, Py_ssize_t size, Py_ssize_t count, Py_ssize_t lo,
                             int64_t key)
{
    Py_ssize_t step = 1, hi = lo;
    while (hi < count && index_at(set, size, hi) < key) {
        lo = hi + 1;
        hi = lo + step - 1;
        step *= 2;
    }
    if (hi > count)
        hi = count;
    while (lo < hi) { /* the first entry not below key lies in [lo, hi] */
        const Py_ssize_t mid = lo + (hi - lo) / 2;
        if (index_at(set, size, mid) < key)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* members(keys, set, found): found[k] = is keys[k] one of set, for integer
 * keys in any order and a set in ascending order (repeats allowed), in one
 * pass: each key is looked for from where the one before it was found, so
 * keys in ascending order (a new Verlet list's pair keys) are merged with
 * the set, and a key below the one before it starts again from the set's
 * start.  keys and set C-contiguous int32 or int64, found writable one-byte
 * flags of the keys' length.  NotImplemented for anything else (the Python
 * side asks NumPy then). */
static PyObject *members(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "members takes keys, set, found");
        return NULL;
    }
    Py_buffer held[3];
    int nheld = 0;
    PyObject *result = Py_NotImplemented;
    if ((nheld = indices_indices_flags(args, held)) < 3)
        goto done;
    const Py_ssize_t n = held[0].shape[0], count = held[1].shape[0];
    if (held[2].readonly || held[2].shape[0] != n)
        goto done;
    const void *keys = held[0].buf, *set = held[1].buf;
    const Py_ssize_t size_keys = held[0].itemsize, size_set = held[1].itemsize;
    char *found = held[2].buf;
    Py_ssize_t at = 0;       /* the place of the key before */
    int64_t before = INT64_MIN;
    for (Py_ssize_t k = 0; k < n; k++) {
        const int64_t key = index_at(keys, size_keys, k);
        at = place_from(set, size_set, count, key < before ? 0 : at, key);
        found[k] = at < count && index_at(set, size_set, at) == key;
        before = key;
    }
    result = Py_None;
done:
    for (int k = 0; k < nheld; k++)
        PyBuffer_Release(&held[k]);
    Py_INCREF(result);
    return result;
}

static PyMethodDef methods[] = {
    {"address", address, METH_O, "The address of a C-contiguous array (None: None)."},
    {"dot_sum", (PyCFunction)(void (*)(void))dot_sum, METH_FASTCALL,
     "sum(a * b) of two C-contiguous float64 arrays of one size (else NotImplemented)."},
    {"damping_work", (PyCFunction)(void (*)(void))damping_work, METH_FASTCALL,
     "-(f . (x - x0) + f_last . (x - x0)) / 2 of C-contiguous float64 arrays of one size, "
     "f, f_last or x0 None (else NotImplemented)."},
    {"all_finite", all_finite, METH_O,
     "Is every element of a C-contiguous float64 array finite? (else NotImplemented)."},
    {"same_bytes", (PyCFunction)(void (*)(void))same_bytes, METH_FASTCALL,
     "Do two C-contiguous buffers hold the same bytes? (else NotImplemented)."},
    {"largest_displacement_squared", (PyCFunction)(void (*)(void))largest_displacement_squared,
     METH_FASTCALL,
     "max |x - x0 - u|^2 over the rows of two n x 3 float64 arrays (else NotImplemented)."},
    {"add_to", (PyCFunction)(void (*)(void))add_to, METH_FASTCALL,
     "a += s * b (times or divided by c) in place, for C-contiguous float64 arrays of one "
     "shape, b and c a itself or apart from it (else NotImplemented)."},
    {"put_rows", (PyCFunction)(void (*)(void))put_rows, METH_FASTCALL,
     "dst[at_b[r], slot_b[r]] = src[r] for the rows r (None: all)."},
    {"pairs_in_order", (PyCFunction)(void (*)(void))pairs_in_order, METH_FASTCALL,
     "The kept pairs of a search's list (i ascending) in order of (i, j), into i_k, j_k "
     "and their rows among the kept pairs into rows_k (else NotImplemented)."},
    {"members", (PyCFunction)(void (*)(void))members, METH_FASTCALL,
     "found[k] = is keys[k] in the ascending set, keys in any order, in one merging pass "
     "(else NotImplemented)."},
    {"any_nonzero", any_nonzero, METH_O,
     "Is some element of a C-contiguous float64 array not zero? (else NotImplemented)."},
    {NULL, NULL, 0, NULL}};

/* The kernels themselves are called through ctypes. */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels",
                                    "ase_bpm's compiled kernels (called through ctypes).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
