/* What every compiled bond and pair kernel shares: the cell, the vector
 * between two atoms, and the per-atom sums of pair forces.
 *
 * The NumPy twins: BondSet.geometry and BondSet.sum_forces
 * (ase_bpm/models/bonded.py), minimum_image (ase_bpm/core/neighbours.py),
 * contact_forces (ase_bpm/laws/contact.py).  Conventions as there: the
 * vector r = x[j] - x[i] points from the first atom to the second; a force
 * magnitude f acts on i along r/|r| (positive: pulls the two together) and
 * its opposite on j.
 */

#ifndef ASE_BPM_BONDS_H
#define ASE_BPM_BONDS_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

/* A function that loops over lanes (spring_law, contact_law), built for
 * AVX2 beside the baseline where GCC can pick one at load time (the same
 * arithmetic: no fused multiply-adds either way) */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define VECTOR_CLONES
#endif

/* what the bond and pair kernels sum, in this order, in `out` (the totals of
 * the Python side: TOTAL_* and BondSums.totals_t, ase_bpm/laws/bond.py) */
enum { OUT_ENERGY, OUT_RELEASED, OUT_VIRIAL, NOUT = OUT_VIRIAL + 9 };

/* The cell as the Python side packs it (ase_bpm/laws/compiled.py, box):
 * kind, three periodic flags, the cell's rows, the inverse's rows. */
enum { BOX_KIND, BOX_PBC, BOX_CELL = 4, BOX_INV = 13, BOX_SIZE = 22 };
enum { BOX_OPEN, BOX_ORTHORHOMBIC, BOX_GENERAL };

/* x rounded to the nearest integer, halves to even (as np.round and
 * nearbyint in the default rounding mode), without a library call: adding
 * and removing 1.5 * 2^52 leaves no fraction bits for |x| < 2^51. */
static inline double round_even(double x)
{
    static const double shifter = 6755399441055744.0; /* 1.5 * 2^52 */
    if (!(fabs(x) < 2251799813685248.0))              /* 2^51, or NaN */
        return nearbyint(x);
    return (x + shifter) - shifter;
}

/* r mapped to its minimum image along the periodic directions, as
 * minimum_image does: per axis in an orthorhombic cell, else through
 * fractional coordinates (rounding half to even, as np.round). */
static inline void minimum_image(const double *box, double *r)
{
    const int kind = (int)box[BOX_KIND];
    if (kind == BOX_OPEN)
        return;
    if (kind == BOX_ORTHORHOMBIC) {
        for (int k = 0; k < 3; k++) {
            const double length = box[BOX_CELL + 4 * k];
            /* within half the cell, r/length rounds to 0: r stays (the common
             * case, without the division) */
            if (box[BOX_PBC + k] != 0.0 && !(fabs(r[k]) < 0.5 * length))
                r[k] -= length * round_even(r[k] / length);
        }
        return;
    }
    double s[3];
    for (int k = 0; k < 3; k++) {
        s[k] = r[0] * box[BOX_INV + k] + r[1] * box[BOX_INV + 3 + k]
               + r[2] * box[BOX_INV + 6 + k];
        if (box[BOX_PBC + k] != 0.0)
            s[k] -= round_even(s[k]);
    }
    for (int k = 0; k < 3; k++)
        r[k] = s[0] * box[BOX_CELL + k] + s[1] * box[BOX_CELL + 3 + k]
               + s[2] * box[BOX_CELL + 6 + k];
}

/* r = x[j] - x[i], minimum image; returns its squared length. */
static inline double bond_vector_squared(const double *x_nc, int64_t i, int64_t j,
                                         const double *box, double *r)
{
    for (int c = 0; c < 3; c++)
        r[c] = x_nc[3 * j + c] - x_nc[3 * i + c];
    minimum_image(box, r);
    return r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
}

/* r = x[j] - x[i], minimum image; returns its length. */
static inline double bond_vector(const double *x_nc, int64_t i, int64_t j, const double *box,
                                 double *r)
{
    return sqrt(bond_vector_squared(x_nc, i, j, box, r));
}

/* The image shift of row x of a neighbour list (shift_xc: three per row, as
 * VerletList.shift_pc), or zeros where the list has none (NULL: built with no
 * periodic direction, ase_bpm/core/neighbours.py).  Adding the zeros keeps
 * the arithmetic of a list that stores them, bit for bit. */
static const double NO_SHIFT[3] = {0.0, 0.0, 0.0};

static inline const double *image_shift(const double *shift_xc, int64_t x)
{
    return shift_xc ? shift_xc + 3 * x : NO_SHIFT;
}

static inline double dot(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* v[j] - v[i] along r */
static inline double relative_speed(const double *v_nc, int64_t i, int64_t j,
                                    const double *r)
{
    double v[3];
    for (int c = 0; c < 3; c++)
        v[c] = v_nc[3 * j + c] - v_nc[3 * i + c];
    return dot(r, v);
}

/* f_nc[i] += s r, f_nc[j] -= s r: the force magnitude s |r| along r on i,
 * its opposite on j. */
static inline void add_pair(double *f_nc, int64_t i, int64_t j, const double *r, double s)
{
    for (int c = 0; c < 3; c++) {
        const double f = r[c] * s;
        f_nc[3 * i + c] += f;
        f_nc[3 * j + c] -= f;
    }
}

/* w += r (x) f for the force f = s r on i (virial, row-major 3x3). */
static inline void add_virial(double *w, const double *r, double s)
{
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            w[3 * a + b] += r[a] * (r[b] * s);
}

/* -- threads ------------------------------------------------------------------
 *
 * A kernel that sums into per-atom forces can run its items (bonds, listed
 * pairs) on threads through run_in_chunks: the items are split into
 * `chunks` contiguous ranges of (nearly) equal length, one per thread; the
 * first range adds straight into the outputs, every other one into buffers
 * of its own (forces, damping forces, the `nout` totals), which are then
 * added to the outputs in the order of the ranges.  Every sum is therefore
 * taken in an order fixed by the item count and `chunks` alone, whatever
 * thread runs which range and when: a run with a fixed thread count gives
 * the same results bit for bit.  Per-item writes (reference lengths,
 * broken-bond marks) go to distinct places from any thread.
 *
 * With one chunk, or in a library built without OpenMP (kernels_openmp in
 * module.c says which), the kernel runs once over all the items, into the
 * outputs: the serial code, unchanged. */

/* A kernel over the items [first, last): adds to f_nc, fd_nc (NULL: no
 * damping part) and out; returns its count (bonds broken, pairs touching). */
typedef int64_t (*chunk_kernel)(const void *args, int64_t first, int64_t last,
                                double *f_nc, double *fd_nc, double *out);

#ifdef _OPENMP
/* run_in_chunks on chunks > 1 threads */
static inline int64_t run_on_threads(chunk_kernel kernel, const void *args, int64_t n,
                                     int64_t chunks, int64_t natoms, double *f_nc,
                                     double *fd_nc, int64_t nout, double *out)
{
    const int64_t size = 3 * natoms;                         /* doubles in f_nc */
    const int64_t stride = (fd_nc ? 2 * size : size) + nout; /* a range's buffers */
    /* malloc, not calloc: each range zeroes its own buffers on its thread, in
     * parallel (calloc would zero them all on this one) */
    double *scratch = malloc(sizeof(double) * (size_t)(stride * (chunks - 1)));
    if (!scratch)
        return -1;
    int64_t count = 0;
#pragma omp parallel num_threads((int)chunks) reduction(+ : count)
    {
#pragma omp for schedule(static, 1)
        for (int64_t c = 0; c < chunks; c++) {
            double *f = f_nc, *fd = fd_nc, *o = out;
            if (c > 0) {
                f = scratch + (c - 1) * stride;
                fd = fd_nc ? f + size : NULL;
                o = f + stride - nout;
                for (int64_t a = 0; a < stride; a++)
                    f[a] = 0.0;
            }
            count += kernel(args, n * c / chunks, n * (c + 1) / chunks, f, fd, o);
        }
        /* (past the loop's barrier: every range is done) the buffers, range by
         * range, each split over the threads; static loops of one length split
         * alike, so each thread adds to the same atoms every time (nowait) */
        for (int64_t c = 1; c < chunks; c++) {
            const double *f = scratch + (c - 1) * stride;
#pragma omp for schedule(static) nowait
            for (int64_t a = 0; a < size; a++)
                f_nc[a] += f[a];
            if (fd_nc) {
#pragma omp for schedule(static) nowait
                for (int64_t a = 0; a < size; a++)
                    fd_nc[a] += f[size + a];
            }
        }
    }
    for (int64_t c = 1; c < chunks; c++)
        for (int64_t k = 0; k < nout; k++)
            out[k] += scratch[c * stride - nout + k];
    free(scratch);
    return count;
}
#endif

/* `kernel` on the n items in `chunks` ranges, as above; natoms: the rows of
 * f_nc and fd_nc, out: `nout` totals.  Returns the sum of the counts, or -1
 * where the buffers cannot be allocated (nothing is added then). */
static inline int64_t run_in_chunks(chunk_kernel kernel, const void *args, int64_t n,
                                    int64_t chunks, int64_t natoms, double *f_nc,
                                    double *fd_nc, int64_t nout, double *out)
{
#ifdef _OPENMP
    if (chunks > 1)
        return run_on_threads(kernel, args, n, chunks, natoms, f_nc, fd_nc, nout, out);
#endif
    return kernel(args, 0, n, f_nc, fd_nc, out);
}

#endif
