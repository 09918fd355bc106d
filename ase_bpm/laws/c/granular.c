/* Compiled granular contact kernels for ase_bpm.
 *
 * The same arithmetic as ase_bpm/laws/granular.py (contact_forces,
 * pair_contacts, walls_contacts), operation for operation: the classic
 * LAMMPS granular laws (pair_style gran/hooke, gran/hooke/history,
 * gran/hertz/history; fix wall/gran).  Plain C called through ctypes
 * (module.c makes the library importable).
 *
 * Geometry: del = x_i - x_j (particle minus wall point for walls); forces on
 * i, the partner gets the opposite; torques -R_i (del x f_t)/r on i and
 * -R_j (del x f_t)/r on j.
 *
 * Contacts go through the law in blocks of LANES, as the spring bonds do
 * (spring.c): one pass finds the touching pairs (or spheres at a wall)
 * among the next LANES rows and gathers what each contact needs into lanes,
 * a second computes the law over the lanes without a branch (contact_law),
 * so that the compiler runs several contacts per vector instruction, and a
 * third adds the forces to the atoms in the order of the contacts.  IEEE
 * arithmetic is the same in vector lanes, and a select gives exactly one of
 * its two values: the results are those of one contact at a time.
 *
 * The law's switches (Hertz, history, its update, friction) reach the
 * kernels from the flags array and the caller's choice of variant (a
 * frictionless one, which computes no tangential velocity, shear or
 * torque: xmu = 0, or Hooke without tangential damping).
 */

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "bonds.h" /* image_shift, VECTOR_CLONES */

/* coefficients, in this order, in the `law` array */
enum { KN, KT, GAMMA_N, GAMMA_T, XMU, DT, NLAW };
/* switches, in this order, in the `flags` array (VIRIAL: pairs only) */
enum { HERTZ, HISTORY, UPDATE, LIMIT_DAMPING, LAMMPS_WALL, VIRIAL, NFLAGS };

/* contacts per block (lanes) */
#define LANES 64

/* A block of touching contacts, one lane each, component by component (so
 * that a vector instruction takes the same component of several contacts).
 * In: del, the radii sum, the two radii, the two masses, whether either
 * sphere is held still (1.0 or 0.0: fix freeze), the
 * relative velocity vr = v_i - v_j, wr = R_i w_i + R_j w_j and the stored
 * shear.  Out: the force on i (f), its elastic part (fel), the torque
 * vector tor = (del x f_t) / r, the elastic energy and the new shear (in
 * place of the stored one). */
struct lanes {
    double del[3][LANES], radsum[LANES], ri[LANES], rj[LANES], mi[LANES], mj[LANES];
    double hold_i[LANES], hold_j[LANES], vr[3][LANES], wr[3][LANES], shear[3][LANES];
    double f[3][LANES], fel[3][LANES], tor[3][LANES], energy[LANES];
};

/* The law's switches for contact_law */
struct switches {
    int frictional, hertz, history, update, lammps_wall, limit_damping;
    int wall; /* the partner is a wall: R_eff = R_i, m_eff = m_i */
};

/* The granular law on the first n lanes of L (LAMMPS' gran pair styles and
 * fix wall/gran, as contact_forces in granular.py): the normal spring and
 * damper ("ccel", the normal force per unit length of del), Hertz's factor,
 * and with friction the tangential force from the shear spring (history) or
 * the damper alone, limited by Coulomb; the shear is updated (history with
 * update).  `frictional` and `history` are constants in each of the three
 * loops compiled from this (contact_law); the other switches choose between
 * values computed both ways, so that the loop has no branch and
 * vectorizes. */
static inline __attribute__((always_inline)) void
law_lanes(int64_t n, struct lanes *restrict L, const double *restrict law, struct switches s,
          const int frictional, const int history)
{
    const double kn = law[KN], kt = law[KT], gamma_n = law[GAMMA_N], gamma_t = law[GAMMA_T];
    const double xmu = law[XMU], dt = law[DT];
    /* the switches as doubles, tested by comparison: GCC 12 vectorizes a
     * select on a comparison of doubles, but not on an int kept from one */
    const double damped = gamma_t != 0.0, damped_n = gamma_n != 0.0;
    const double hertz = s.hertz, update = s.update, lammps_wall = s.lammps_wall;
    const double limit_damping = s.limit_damping, wall = s.wall;
    const double hertz_damper = s.lammps_wall && s.hertz && gamma_t != 0.0;
    const double hertz_spring = s.hertz && !s.lammps_wall;
    for (int64_t k = 0; k < n; k++) {
        const double d0 = L->del[0][k], d1 = L->del[1][k], d2 = L->del[2][k];
        const double rsq = d0 * d0 + d1 * d1 + d2 * d2;
        const double r = sqrt(rsq);
        const double rinv = 1.0 / r;
        const double rsqinv = 1.0 / rsq;
        const double overlap = L->radsum[k] - r;
        const double ri = L->ri[k], rj = L->rj[k], mi = L->mi[k], mj = L->mj[k];
        /* fix freeze: a held partner counts as a wall */
        const double both = mi * mj / (mi + mj);
        const double meff = wall != 0.0            ? mi
                            : L->hold_j[k] != 0.0 ? mi
                            : L->hold_i[k] != 0.0 ? mj
                                                  : both;
        const double paired = ri * rj / L->radsum[k];
        const double reff = wall != 0.0 ? ri : paired;
        const double v0 = L->vr[0][k], v1 = L->vr[1][k], v2 = L->vr[2][k];
        const double vdel = v0 * d0 + v1 * d1 + v2 * d2;
        const double vnnr = frictional || damped_n != 0.0 ? vdel : 0.0;

        /* normal part */
        const double spring_n = kn * overlap * rinv;
        const double ccel_n =
            damped_n != 0.0 ? spring_n - meff * gamma_n * vnnr * rsqinv : spring_n;
        const double root = sqrt(overlap * reff); /* Hertz's factor, the contact radius */
        const double polyhertz = hertz != 0.0 ? root : 0.0;
        double ccel = hertz != 0.0 ? ccel_n * polyhertz : ccel_n;
        const double elastic = hertz != 0.0 ? spring_n * polyhertz : spring_n;
        const double energy_hertz = 0.4 * kn * polyhertz * overlap * overlap;
        const double energy_hooke = 0.5 * kn * overlap * overlap;
        L->energy[k] = hertz != 0.0 ? energy_hertz : energy_hooke;
        ccel = limit_damping != 0.0 && ccel < 0.0 ? 0.0 : ccel;

        double fs0 = 0.0, fs1 = 0.0, fs2 = 0.0;
        if (frictional) {
            /* relative velocity of the surfaces, tangential part */
            const double along = vnnr * rsqinv;
            const double vt0 = v0 - d0 * along, vt1 = v1 - d1 * along, vt2 = v2 - d2 * along;
            const double w0 = L->wr[0][k] * rinv, w1 = L->wr[1][k] * rinv;
            const double w2 = L->wr[2][k] * rinv;
            const double vtr0 = vt0 - (w1 * d2 - w2 * d1);
            const double vtr1 = vt1 - (w2 * d0 - w0 * d2);
            const double vtr2 = vt2 - (w0 * d1 - w1 * d0);
            const double fn = xmu * fabs(ccel * r); /* Coulomb limit */
            const double damp0 = damped != 0.0 ? (meff * gamma_t) * vtr0 : 0.0;
            const double damp1 = damped != 0.0 ? (meff * gamma_t) * vtr1 : 0.0;
            const double damp2 = damped != 0.0 ? (meff * gamma_t) * vtr2 : 0.0;
            if (!history) { /* the damper alone, limited */
                const double vrel = sqrt(vtr0 * vtr0 + vtr1 * vtr1 + vtr2 * vtr2);
                const double fsmag = meff * gamma_t * vrel;
                const double ft = vrel != 0.0 ? (fn < fsmag ? fn : fsmag) / vrel : 0.0;
                fs0 = damped != 0.0 ? -ft * vtr0 : 0.0;
                fs1 = damped != 0.0 ? -ft * vtr1 : 0.0;
                fs2 = damped != 0.0 ? -ft * vtr2 : 0.0;
            } else {
                double h0 = L->shear[0][k], h1 = L->shear[1][k], h2 = L->shear[2][k];
                h0 = update != 0.0 ? h0 + vtr0 * dt : h0;
                h1 = update != 0.0 ? h1 + vtr1 * dt : h1;
                h2 = update != 0.0 ? h2 + vtr2 * dt : h2;
                const double shrsq = h0 * h0 + h1 * h1 + h2 * h2;
                /* kept in the tangent plane */
                const double rsht = (h0 * d0 + h1 * d1 + h2 * d2) * rsqinv;
                h0 = update != 0.0 ? h0 - d0 * rsht : h0;
                h1 = update != 0.0 ? h1 - d1 * rsht : h1;
                h2 = update != 0.0 ? h2 - d2 * rsht : h2;
                /* the reference build's wall: a spring of kt times the
                 * contact radius, and Hertz's factor on the damper only */
                const double e0 = hertz_damper != 0.0 ? damp0 * polyhertz : damp0;
                const double e1 = hertz_damper != 0.0 ? damp1 * polyhertz : damp1;
                const double e2 = hertz_damper != 0.0 ? damp2 * polyhertz : damp2;
                const double kwall = -kt * root;
                fs0 = lammps_wall != 0.0 ? kwall * h0 : -kt * h0;
                fs1 = lammps_wall != 0.0 ? kwall * h1 : -kt * h1;
                fs2 = lammps_wall != 0.0 ? kwall * h2 : -kt * h2;
                fs0 = damped != 0.0 ? fs0 - e0 : fs0;
                fs1 = damped != 0.0 ? fs1 - e1 : fs1;
                fs2 = damped != 0.0 ? fs2 - e2 : fs2;
                fs0 = hertz_spring != 0.0 ? fs0 * polyhertz : fs0;
                fs1 = hertz_spring != 0.0 ? fs1 * polyhertz : fs1;
                fs2 = hertz_spring != 0.0 ? fs2 * polyhertz : fs2;
                /* at the Coulomb limit (squares compared, as in granular.py):
                 * the force scaled down, and the spring to what is left of it
                 * after the damper; no spring yet, no force */
                const double fssq = fs0 * fs0 + fs1 * fs1 + fs2 * fs2;
                const double scale = fn / sqrt(fssq);
                const double lag0 = e0 / kt, lag1 = e1 / kt, lag2 = e2 / kt;
                const double g0 = lammps_wall != 0.0 ? -(fs0 * scale + e0) / kt
                                              : scale * (h0 + lag0) - lag0;
                const double g1 = lammps_wall != 0.0 ? -(fs1 * scale + e1) / kt
                                              : scale * (h1 + lag1) - lag1;
                const double g2 = lammps_wall != 0.0 ? -(fs2 * scale + e2) / kt
                                              : scale * (h2 + lag2) - lag2;
                /* (each select on a comparison written out: see above) */
                const double reset0 = shrsq != 0.0 ? g0 : h0, reset1 = shrsq != 0.0 ? g1 : h1;
                const double reset2 = shrsq != 0.0 ? g2 : h2;
                L->shear[0][k] = fssq > fn * fn ? reset0 : h0;
                L->shear[1][k] = fssq > fn * fn ? reset1 : h1;
                L->shear[2][k] = fssq > fn * fn ? reset2 : h2;
                const double scaled0 = shrsq != 0.0 ? fs0 * scale : 0.0;
                const double scaled1 = shrsq != 0.0 ? fs1 * scale : 0.0;
                const double scaled2 = shrsq != 0.0 ? fs2 * scale : 0.0;
                fs0 = fssq > fn * fn ? scaled0 : fs0;
                fs1 = fssq > fn * fn ? scaled1 : fs1;
                fs2 = fssq > fn * fn ? scaled2 : fs2;
            }
        }
        L->fel[0][k] = d0 * elastic;
        L->fel[1][k] = d1 * elastic;
        L->fel[2][k] = d2 * elastic;
        L->f[0][k] = d0 * ccel + fs0;
        L->f[1][k] = d1 * ccel + fs1;
        L->f[2][k] = d2 * ccel + fs2;
        L->tor[0][k] = (d1 * fs2 - d2 * fs1) * rinv;
        L->tor[1][k] = (d2 * fs0 - d0 * fs2) * rinv;
        L->tor[2][k] = (d0 * fs1 - d1 * fs0) * rinv;
    }
}

VECTOR_CLONES static void law_frictionless(int64_t n, struct lanes *restrict L,
                                           const double *restrict law, struct switches s)
{
    law_lanes(n, L, law, s, 0, 0);
}

VECTOR_CLONES static void law_damper(int64_t n, struct lanes *restrict L,
                                     const double *restrict law, struct switches s)
{
    law_lanes(n, L, law, s, 1, 0);
}

VECTOR_CLONES static void law_history(int64_t n, struct lanes *restrict L,
                                      const double *restrict law, struct switches s)
{
    law_lanes(n, L, law, s, 1, 1);
}

/* The law on n lanes, in the loop compiled for the law's friction */
static void contact_law(int64_t n, struct lanes *L, const double *law, struct switches s)
{
    if (!s.frictional)
        law_frictionless(n, L, law, s);
    else if (!s.history)
        law_damper(n, L, law, s);
    else
        law_history(n, L, law, s);
}

/* Contacts of the listed sphere pairs (a neighbour list, rows l), with or
 * without friction (`frictional`, a constant in each of the two kernels
 * below, so the compiler leaves out what the frictionless one does not
 * need).
 *
 * For each row: r = x_j - x_i + shift (shift_lc NULL: no shifts, an open
 * box), del = -r; touching when |del|^2 < (R_i + R_j)^2.  The touching rows
 * go to touch_l (3 x nl: the rows from touch_l[0], their i from touch_l[nl],
 * their j from touch_l[2 nl]; their count is returned), and each sphere's
 * number of touching partners is added to count_n.  History models read each
 * row's stored shear from shear_lc (left as it is) and write the new shear
 * of every row to new_shear_lc (zero where not touching) and of the touching
 * ones, in their order, to touch_shear_tc.  Forces (f_nc), their dissipative
 * part (all but the normal springs: fd_nc) and torques (t_nc, frictional
 * only) are added to the per-atom arrays, which the caller zeroes.  out[0]
 * += elastic energy, out[1 + 3a + b] += sum of r_a f_b (the virial, if
 * flags[VIRIAL]).  The three shear arrays are read or written by history
 * models only (else may be NULL), w_nc and t_nc with friction only, v_nc
 * with friction or gamma_n.  A touching pair at zero distance stops the
 * kernel: returns -1 - row.  On `threads` threads where built with OpenMP
 * (pairs_on_threads; 1: serially); returns PAIRS_NO_MEMORY where the
 * threads' buffers cannot be allocated. */

/* the inputs and per-row outputs of the pair kernel (the per-atom sums and
 * totals are passed apart: each thread has its own) */
struct pair_args {
    int64_t nl;
    const int64_t *i_l, *j_l;
    const double *shift_lc, *x_nc, *v_nc, *w_nc, *r_n, *m_n;
    const int8_t *hold_n;
    const double *shear_lc, *law;
    const int64_t *flags;
    double *new_shear_lc, *touch_shear_tc;
    int64_t *touch_l;
};

/* the totals of the pair kernel: energy and virial */
enum { PAIRS_NOUT = 10 };
#define PAIRS_NO_MEMORY INT64_MIN /* (compiled.py: _NO_MEMORY) */

/* The pair kernel on the rows [start, stop): their touching rows go to
 * touch_l (and their shear to touch_shear_tc) from place `start` on;
 * returns their count, or -1 - row for a pair at zero distance. */
static inline __attribute__((always_inline)) int64_t
pairs_range(const struct pair_args *a, int64_t start, int64_t stop, double *f_nc,
            double *fd_nc, double *t_nc, int64_t *count_n, double *out, const int frictional)
{
    const int64_t nl = a->nl, *i_l = a->i_l, *j_l = a->j_l, *flags = a->flags;
    const double *shift_lc = a->shift_lc, *x_nc = a->x_nc, *v_nc = a->v_nc, *w_nc = a->w_nc;
    const double *r_n = a->r_n, *m_n = a->m_n, *shear_lc = a->shear_lc, *law = a->law;
    const int8_t *hold_n = a->hold_n;
    double *new_shear_lc = a->new_shear_lc, *touch_shear_tc = a->touch_shear_tc;
    int64_t *touch_l = a->touch_l;
    const struct switches s = {frictional, (int)flags[HERTZ], frictional && flags[HISTORY],
                               (int)flags[UPDATE], 0, (int)flags[LIMIT_DAMPING], 0};
    const int want_virial = (int)flags[VIRIAL];
    const int need_v = frictional || law[GAMMA_N] != 0.0;
    int64_t ntouch = start;
    double energy = 0.0, w[9] = {0.0};
    struct lanes L;
    for (int64_t first = start; first < stop; first += LANES) {
        const int64_t end = stop - first < LANES ? stop : first + LANES;
        const int64_t before = ntouch;
        int64_t n = 0;
        for (int64_t l = first; l < end; l++) { /* gather the touching rows */
            const int64_t i = i_l[l], j = j_l[l];
            const double *shift = image_shift(shift_lc, l);
            double del[3];
            for (int c = 0; c < 3; c++)
                del[c] = -((x_nc[3 * j + c] - x_nc[3 * i + c]) + shift[c]);
            const double radsum = r_n[i] + r_n[j];
            const double rsq = dot(del, del);
            if (!(rsq < radsum * radsum)) {
                if (s.history)
                    for (int c = 0; c < 3; c++)
                        new_shear_lc[3 * l + c] = 0.0;
                continue;
            }
            if (rsq < DBL_MIN) /* coincident, or so close that 1 / r^2 overflows */
                return -1 - l;
            touch_l[ntouch] = l;
            touch_l[nl + ntouch] = i;
            touch_l[2 * nl + ntouch] = j;
            ntouch++;
            L.radsum[n] = radsum;
            L.ri[n] = r_n[i];
            L.rj[n] = r_n[j];
            L.mi[n] = m_n[i];
            L.mj[n] = m_n[j];
            L.hold_i[n] = hold_n && hold_n[i] ? 1.0 : 0.0;
            L.hold_j[n] = hold_n && hold_n[j] ? 1.0 : 0.0;
            for (int c = 0; c < 3; c++) {
                L.del[c][n] = del[c];
                L.vr[c][n] = need_v ? v_nc[3 * i + c] - v_nc[3 * j + c] : 0.0;
                L.wr[c][n] = frictional ? r_n[i] * w_nc[3 * i + c] + r_n[j] * w_nc[3 * j + c]
                                        : 0.0;
                L.shear[c][n] = s.history ? shear_lc[3 * l + c] : 0.0;
            }
            n++;
        }
        contact_law(n, &L, law, s);
        for (int64_t k = 0; k < n; k++) { /* add, in the order of the rows */
            const int64_t l = touch_l[before + k], i = i_l[l], j = j_l[l];
            for (int c = 0; c < 3; c++) {
                const double f = L.f[c][k], fd = f - L.fel[c][k];
                f_nc[3 * i + c] += f;
                f_nc[3 * j + c] -= f;
                fd_nc[3 * i + c] += fd;
                fd_nc[3 * j + c] -= fd;
            }
            if (frictional)
                for (int c = 0; c < 3; c++) {
                    t_nc[3 * i + c] += -L.ri[k] * L.tor[c][k];
                    t_nc[3 * j + c] += -L.rj[k] * L.tor[c][k];
                }
            if (s.history)
                for (int c = 0; c < 3; c++)
                    new_shear_lc[3 * l + c] = touch_shear_tc[3 * (before + k) + c] =
                        L.shear[c][k];
            count_n[i]++;
            count_n[j]++;
            energy += L.energy[k];
            if (want_virial)
                for (int a = 0; a < 3; a++)
                    for (int b = 0; b < 3; b++)
                        w[3 * a + b] += -L.del[a][k] * L.f[b][k];
        }
    }
    out[0] += energy;
    for (int k = 0; k < 9; k++)
        out[1 + k] += w[k];
    return ntouch - start;
}

#ifdef _OPENMP
/* The pair kernel on `chunks` > 1 threads: the rows in contiguous ranges of
 * (nearly) equal length, one per thread, the first adding straight into the
 * outputs, each other one into buffers of its own (forces, damping forces,
 * torques, totals, counts) that are then added in the order of the ranges;
 * the touching rows of each range, written from its first row's place on,
 * are then moved up behind those of the range before.  Every sum is taken
 * in an order fixed by the row count and `chunks` alone (the same results
 * bit for bit every time); the per-row outputs are those of one thread. */
static int64_t pairs_on_threads(const struct pair_args *a, double *f_nc, double *fd_nc,
                                double *t_nc, int64_t *count_n, double *out, int64_t chunks,
                                int64_t natoms, const int frictional)
{
    const int64_t nl = a->nl, size = 3 * natoms;
    const int64_t stride = (frictional ? 3 : 2) * size + PAIRS_NOUT; /* a range's doubles */
    double *scratch = malloc(sizeof(double) * (size_t)(stride * (chunks - 1)));
    int64_t *tally = malloc(sizeof(int64_t) * (size_t)(natoms * (chunks - 1) + chunks));
    if (!scratch || !tally) {
        free(scratch);
        free(tally);
        return PAIRS_NO_MEMORY;
    }
    int64_t *result = tally + natoms * (chunks - 1);
#pragma omp parallel for num_threads((int)chunks) schedule(static, 1)
    for (int64_t c = 0; c < chunks; c++) {
        double *f = f_nc, *fd = fd_nc, *t = t_nc, *o = out;
        int64_t *count = count_n;
        if (c > 0) {
            f = scratch + (c - 1) * stride;
            fd = f + size;
            t = frictional ? fd + size : NULL;
            o = f + stride - PAIRS_NOUT;
            count = tally + (c - 1) * natoms;
            for (int64_t k = 0; k < stride; k++)
                f[k] = 0.0;
            for (int64_t k = 0; k < natoms; k++)
                count[k] = 0;
        }
        result[c] = pairs_range(a, nl * c / chunks, nl * (c + 1) / chunks, f, fd, t, count, o,
                                frictional);
    }
    int64_t total = 0;
    for (int64_t c = 0; c < chunks && total >= 0; c++)
        if (result[c] < 0)
            total = result[c]; /* the first range that stopped: the lowest such row */
    for (int64_t c = 1; c < chunks && total >= 0; c++) {
        const double *f = scratch + (c - 1) * stride;
        for (int64_t k = 0; k < size; k++) {
            f_nc[k] += f[k];
            fd_nc[k] += f[size + k];
        }
        if (frictional)
            for (int64_t k = 0; k < size; k++)
                t_nc[k] += f[2 * size + k];
        for (int64_t k = 0; k < PAIRS_NOUT; k++)
            out[k] += f[stride - PAIRS_NOUT + k];
        for (int64_t k = 0; k < natoms; k++)
            count_n[k] += tally[(c - 1) * natoms + k];
    }
    if (total >= 0) {
        total = result[0];
        for (int64_t c = 1; c < chunks; c++) { /* the touching rows, behind the range before */
            const int64_t from = nl * c / chunks, n = result[c];
            for (int row = 0; row < 3; row++)
                memmove(a->touch_l + row * nl + total, a->touch_l + row * nl + from,
                        sizeof(int64_t) * (size_t)n);
            if (a->touch_shear_tc)
                memmove(a->touch_shear_tc + 3 * total, a->touch_shear_tc + 3 * from,
                        sizeof(double) * (size_t)(3 * n));
            total += n;
        }
    }
    free(scratch);
    free(tally);
    return total;
}
#endif

static inline __attribute__((always_inline)) int64_t
pairs(const struct pair_args *a, double *f_nc, double *fd_nc, double *t_nc, int64_t *count_n,
      double *out, int64_t threads, int64_t natoms, const int frictional)
{
#ifdef _OPENMP
    if (threads > 1)
        return pairs_on_threads(a, f_nc, fd_nc, t_nc, count_n, out, threads, natoms,
                                frictional);
#endif
    (void)threads;
    (void)natoms;
    return pairs_range(a, 0, a->nl, f_nc, fd_nc, t_nc, count_n, out, frictional);
}

int64_t granular_pairs(int64_t nl, const int64_t *i_l, const int64_t *j_l,
                       const double *shift_lc, const double *x_nc, const double *v_nc,
                       const double *w_nc, const double *r_n, const double *m_n,
                       const int8_t *hold_n, const double *shear_lc, const double *law,
                       const int64_t *flags, double *new_shear_lc, double *touch_shear_tc,
                       double *f_nc, double *fd_nc, double *t_nc, int64_t *touch_l,
                       int64_t *count_n, double *out, int64_t natoms, int64_t threads)
{
    const struct pair_args a = {nl, i_l, j_l, shift_lc, x_nc, v_nc, w_nc, r_n, m_n, hold_n,
                                shear_lc, law, flags, new_shear_lc, touch_shear_tc, touch_l};
    return pairs(&a, f_nc, fd_nc, t_nc, count_n, out, threads, natoms, 1);
}

int64_t granular_pairs_frictionless(int64_t nl, const int64_t *i_l, const int64_t *j_l,
                                    const double *shift_lc, const double *x_nc,
                                    const double *v_nc, const double *w_nc, const double *r_n,
                                    const double *m_n, const int8_t *hold_n,
                                    const double *shear_lc, const double *law,
                                    const int64_t *flags, double *new_shear_lc,
                                    double *touch_shear_tc, double *f_nc, double *fd_nc,
                                    double *t_nc, int64_t *touch_l, int64_t *count_n,
                                    double *out, int64_t natoms, int64_t threads)
{
    const struct pair_args a = {nl, i_l, j_l, shift_lc, x_nc, v_nc, w_nc, r_n, m_n, hold_n,
                                shear_lc, law, flags, new_shear_lc, touch_shear_tc, touch_l};
    return pairs(&a, f_nc, fd_nc, t_nc, count_n, out, threads, natoms, 0);
}

/* Contacts of every sphere with flat walls: wall w is the plane
 * x[axis_w[w]] = lo_w[w] (spheres above it) and/or x[axis_w[w]] = hi_w[w]
 * (spheres below it), -INFINITY and INFINITY where it has no such side.  A
 * wall is a partner of radius 0 and infinite mass at rest.  Forces are
 * added, wall after wall, to f_nc, their dissipative part (all but the
 * normal springs) to fd_nc and torques (frictional only) to t_nc, which the
 * caller zeroes; the touching spheres are listed in touch_x, wall after
 * wall, and their count is returned.  History models read each wall's
 * stored shear per sphere from stored_w[w] (n x 3; left as it is; a NULL
 * there: none stored, zero) and write the new one, zero where not touching,
 * to shear_wnc (nw x n x 3).  out[0] += elastic energy.  Without friction
 * w_nc, stored_w, shear_wnc and t_nc are not read (may be NULL), nor v_nc
 * when gamma_n is 0.  A sphere centred on a wall stops the kernel: returns
 * -1 - (w n + sphere). */
static inline __attribute__((always_inline)) int64_t
walls(int64_t n, int64_t nw, const int64_t *axis_w, const double *lo_w, const double *hi_w,
      const double *x_nc, const double *v_nc, const double *w_nc, const double *r_n,
      const double *m_n, const double *const *stored_w, double *shear_wnc,
      const double *law, const int64_t *flags, double *f_nc, double *fd_nc, double *t_nc,
      int64_t *touch_x, double *out, const int frictional)
{
    const struct switches s = {frictional, (int)flags[HERTZ], frictional && flags[HISTORY],
                               (int)flags[UPDATE], (int)flags[LAMMPS_WALL],
                               (int)flags[LIMIT_DAMPING], 1};
    const int need_v = frictional || law[GAMMA_N] != 0.0;
    int64_t ntouch = 0;
    struct lanes L;
    for (int64_t w = 0; w < nw; w++) {
        const int64_t axis = axis_w[w];
        const double lo = lo_w[w], hi = hi_w[w];
        const double *stored = s.history && stored_w ? stored_w[w] : NULL;
        double *shear_nc = s.history ? shear_wnc + 3 * n * w : NULL;
        for (int64_t first = 0; first < n; first += LANES) {
            const int64_t end = n - first < LANES ? n : first + LANES;
            const int64_t before = ntouch;
            int64_t m = 0;
            for (int64_t i = first; i < end; i++) { /* gather the touching spheres */
                const double x = x_nc[3 * i + axis], rad = r_n[i];
                const double below = x - lo, above = hi - x;
                const double dx = below < above ? below : -above;
                if (!(dx * dx < rad * rad)) {
                    if (shear_nc)
                        shear_nc[3 * i] = shear_nc[3 * i + 1] = shear_nc[3 * i + 2] = 0.0;
                    continue;
                }
                if (dx == 0.0)
                    return -1 - (w * n + i);
                touch_x[ntouch++] = i;
                L.radsum[m] = L.ri[m] = L.rj[m] = rad;
                L.mi[m] = m_n[i];
                L.mj[m] = 1.0; /* not used: the partner is a wall */
                L.hold_i[m] = L.hold_j[m] = 0.0;
                for (int c = 0; c < 3; c++) {
                    L.del[c][m] = c == axis ? dx : 0.0;
                    L.vr[c][m] = need_v ? v_nc[3 * i + c] : 0.0;
                    L.wr[c][m] = frictional ? rad * w_nc[3 * i + c] : 0.0;
                    L.shear[c][m] = stored ? stored[3 * i + c] : 0.0;
                }
                m++;
            }
            contact_law(m, &L, law, s);
            for (int64_t k = 0; k < m; k++) { /* add, in the order of the spheres */
                const int64_t i = touch_x[before + k];
                for (int c = 0; c < 3; c++) {
                    f_nc[3 * i + c] += L.f[c][k];
                    fd_nc[3 * i + c] += L.f[c][k] - L.fel[c][k];
                }
                if (frictional)
                    for (int c = 0; c < 3; c++)
                        t_nc[3 * i + c] += -L.ri[k] * L.tor[c][k];
                if (shear_nc)
                    for (int c = 0; c < 3; c++)
                        shear_nc[3 * i + c] = L.shear[c][k];
                out[0] += L.energy[k];
            }
        }
    }
    return ntouch;
}

int64_t granular_walls(int64_t n, int64_t nw, const int64_t *axis_w, const double *lo_w,
                       const double *hi_w, const double *x_nc, const double *v_nc,
                       const double *w_nc, const double *r_n, const double *m_n,
                       const double *const *stored_w, double *shear_wnc,
                       const double *law, const int64_t *flags, double *f_nc, double *fd_nc,
                       double *t_nc, int64_t *touch_x, double *out)
{
    return walls(n, nw, axis_w, lo_w, hi_w, x_nc, v_nc, w_nc, r_n, m_n, stored_w, shear_wnc,
                 law, flags, f_nc, fd_nc, t_nc, touch_x, out, 1);
}

int64_t granular_walls_frictionless(int64_t n, int64_t nw, const int64_t *axis_w,
                                    const double *lo_w, const double *hi_w,
                                    const double *x_nc, const double *v_nc,
                                    const double *w_nc, const double *r_n, const double *m_n,
                                    const double *const *stored_w, double *shear_wnc,
                                    const double *law, const int64_t *flags, double *f_nc,
                                    double *fd_nc, double *t_nc, int64_t *touch_x,
                                    double *out)
{
    return walls(n, nw, axis_w, lo_w, hi_w, x_nc, v_nc, w_nc, r_n, m_n, stored_w, shear_wnc,
                 law, flags, f_nc, fd_nc, t_nc, touch_x, out, 0);
}

/* The shear history's place on the atoms (models/contacts.py,
 * write_contacts): contact k (i_k < j_k, the contacts in order of i) goes to
 * slot s of atom i_k, s its rank among the contacts of i_k, in arrays of
 * `width` slots per atom: partner_nw[i width + s] = ids_n[j_k], the three
 * numbers of row i width + s of shear_nw3 = shear_kc[k], and at_k[k] = i
 * width + s.  The slots at_old (nold of them: those of the contacts written
 * before) are emptied first.  Returns the width the contacts need (the
 * largest count of one atom, at least 1); when that is not `width`, nothing
 * is written (the caller makes arrays of that width and calls again).  An
 * old slot outside the n atoms' arrays writes nothing and returns -1. */
int64_t granular_place_contacts(int64_t n, int64_t nk, const int64_t *i_k, const int64_t *j_k,
                                const int64_t *ids_n, const double *shear_kc, int64_t nold,
                                const int64_t *at_old, int64_t width, int64_t *partner_nw,
                                double *shear_nw3, int64_t *at_k)
{
    int64_t need = 1, rank = 0;
    for (int64_t k = 0; k < nk; k++) {
        rank = k > 0 && i_k[k] == i_k[k - 1] ? rank + 1 : 0;
        at_k[k] = rank;
        if (rank + 1 > need)
            need = rank + 1;
    }
    if (need != width)
        return need;
    for (int64_t o = 0; o < nold; o++)
        if (at_old[o] < 0 || at_old[o] >= n * width)
            return -1;
    for (int64_t o = 0; o < nold; o++) {
        const int64_t at = at_old[o];
        partner_nw[at] = 0;
        shear_nw3[3 * at] = shear_nw3[3 * at + 1] = shear_nw3[3 * at + 2] = 0.0;
    }
    for (int64_t k = 0; k < nk; k++) {
        const int64_t at = i_k[k] * width + at_k[k];
        partner_nw[at] = ids_n[j_k[k]];
        for (int c = 0; c < 3; c++)
            shear_nw3[3 * at + c] = shear_kc[3 * k + c];
        at_k[k] = at;
    }
    return need;
}
