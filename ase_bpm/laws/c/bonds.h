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

#endif
