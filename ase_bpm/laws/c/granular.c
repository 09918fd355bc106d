/* Compiled granular contact kernels for ase_bpm.
 *
 * The same arithmetic as ase_bpm/laws/granular.py (contact_forces,
 * pair_contacts, walls_contacts), operation for operation, over one contact at
 * a time: the classic LAMMPS granular laws (pair_style gran/hooke,
 * gran/hooke/history, gran/hertz/history; fix wall/gran).  Plain C called
 * through ctypes (module.c makes the library importable).
 *
 * Geometry: del = x_i - x_j (particle minus wall point for walls); forces on
 * i, the partner gets the opposite; torques -R_i (del x f_t)/r on i and
 * -R_j (del x f_t)/r on j.
 *
 * Two variants of each kernel, chosen once by the caller from the
 * coefficients: the general one and a frictionless one (no tangential force
 * can act: xmu = 0, or Hooke without tangential damping), which computes no
 * tangential velocity, shear or torque.
 *
 * The law's switches (Hertz, history, its update) reach the contact as
 * compile-time constants: the pair kernels branch on them once per call into
 * a loop specialised for them, with the contact inlined.  Read from the flags
 * array inside the loop, they cost a third of the time of a pour's contacts.
 */

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "bonds.h" /* image_shift */

/* coefficients, in this order, in the `law` array */
enum { KN, KT, GAMMA_N, GAMMA_T, XMU, DT, NLAW };
/* switches, in this order, in the `flags` array (VIRIAL: pairs only) */
enum { HERTZ, HISTORY, UPDATE, LIMIT_DAMPING, LAMMPS_WALL, VIRIAL, NFLAGS };

static inline double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The normal part of one touching contact: returns LAMMPS' "ccel", the
 * normal force per unit length of del, and writes its elastic (normal spring)
 * part and the elastic energy; *polyhertz gets the Hertz factor (0 for
 * Hooke).  vnnr = vr . del is read only when gamma_n is not 0. */
static inline __attribute__((always_inline)) double
normal_part(double rinv, double rsqinv, double overlap, double reff, double vnnr, double meff,
            const double *law, const int64_t *flags, const int hertz, double *elastic_out,
            double *polyhertz_out, double *energy_out)
{
    const double kn = law[KN], gamma_n = law[GAMMA_N];
    double elastic = kn * overlap * rinv;
    double ccel = gamma_n != 0.0 ? elastic - meff * gamma_n * vnnr * rsqinv : elastic;
    double polyhertz = 0.0;
    if (hertz) {
        polyhertz = sqrt(overlap * reff);
        ccel = ccel * polyhertz;
        elastic = elastic * polyhertz;
        *energy_out = 0.4 * kn * polyhertz * overlap * overlap;
    } else {
        *energy_out = 0.5 * kn * overlap * overlap;
    }
    if (flags[LIMIT_DAMPING] && ccel < 0.0)
        ccel = 0.0;
    *elastic_out = elastic;
    *polyhertz_out = polyhertz;
    return ccel;
}

/* One touching contact without friction (the frictionless variant: no
 * tangential force can act, so no tangential velocity, shear or torque is
 * computed).  `vr` may be NULL when gamma_n is 0.  Out: total force f and its
 * elastic part fel; returns the elastic energy. */
static inline __attribute__((always_inline)) double
contact_frictionless(const double *del, double radsum, double reff, const double *vr,
                     double meff, const double *law, const int64_t *flags, const int hertz,
                     double *f, double *fel)
{
    double rsq = dot3(del, del);
    double r = sqrt(rsq);
    double rinv = 1.0 / r;
    double rsqinv = 1.0 / rsq;
    double overlap = radsum - r;
    double vnnr = law[GAMMA_N] != 0.0 ? dot3(vr, del) : 0.0;
    double elastic, polyhertz, energy;
    double ccel = normal_part(rinv, rsqinv, overlap, reff, vnnr, meff, law, flags, hertz,
                              &elastic, &polyhertz, &energy);
    for (int c = 0; c < 3; c++) {
        fel[c] = del[c] * elastic;
        f[c] = del[c] * ccel;
    }
    return energy;
}

/* One touching contact.  `shear` (history models) holds the stored shear and
 * receives the new one.  The switches hertz, history, update and wall are
 * those of the flags array (LAMMPS_WALL for wall).  Out: total force f, its
 * elastic (normal spring) part fel, the torque vector tor = (del x f_t) / r;
 * returns the elastic energy. */
static inline __attribute__((always_inline)) double
contact(const double *del, double radsum, double reff, const double *vr, const double *wr,
        double meff, double *shear, const double *law, const int64_t *flags, const int hertz,
        const int history, const int update, const int wall, double *f, double *fel,
        double *tor)
{
    const double kt = law[KT], gamma_t = law[GAMMA_T], xmu = law[XMU], dt = law[DT];

    double rsq = dot3(del, del);
    double r = sqrt(rsq);
    double rinv = 1.0 / r;
    double rsqinv = 1.0 / rsq;
    double overlap = radsum - r;

    /* relative velocity: normal and tangential parts, and of the surfaces */
    double vnnr = dot3(vr, del);
    double vt[3], wrr[3], vtr[3];
    for (int c = 0; c < 3; c++) {
        vt[c] = vr[c] - del[c] * (vnnr * rsqinv);
        wrr[c] = wr[c] * rinv;
    }
    vtr[0] = vt[0] - (wrr[1] * del[2] - wrr[2] * del[1]);
    vtr[1] = vt[1] - (wrr[2] * del[0] - wrr[0] * del[2]);
    vtr[2] = vt[2] - (wrr[0] * del[1] - wrr[1] * del[0]);

    double elastic, polyhertz, energy;
    double ccel = normal_part(rinv, rsqinv, overlap, reff, vnnr, meff, law, flags, hertz,
                              &elastic, &polyhertz, &energy);
    double fn = xmu * fabs(ccel * r); /* Coulomb limit */
    int damped = gamma_t != 0.0;
    double damp[3] = {0.0, 0.0, 0.0};
    if (damped)
        for (int c = 0; c < 3; c++)
            damp[c] = (meff * gamma_t) * vtr[c];

    double fs[3];
    if (!history && !damped) {
        fs[0] = fs[1] = fs[2] = 0.0;
    } else if (!history) {
        double vrel = sqrt(dot3(vtr, vtr));
        double fsmag = meff * gamma_t * vrel;
        double ft = vrel != 0.0 ? (fn < fsmag ? fn : fsmag) / vrel : 0.0;
        for (int c = 0; c < 3; c++)
            fs[c] = -ft * vtr[c];
    } else {
        if (update)
            for (int c = 0; c < 3; c++)
                shear[c] += vtr[c] * dt;
        double shrsq = dot3(shear, shear);
        if (update) {
            double rsht = dot3(shear, del) * rsqinv;
            for (int c = 0; c < 3; c++)
                shear[c] -= del[c] * rsht;
        }
        if (wall) {
            if (hertz && damped)
                for (int c = 0; c < 3; c++)
                    damp[c] *= polyhertz;
            double spring = sqrt(overlap * reff); /* the contact radius */
            for (int c = 0; c < 3; c++)
                fs[c] = -kt * spring * shear[c];
        } else {
            for (int c = 0; c < 3; c++)
                fs[c] = -kt * shear[c];
        }
        if (damped)
            for (int c = 0; c < 3; c++)
                fs[c] -= damp[c];
        if (hertz && !wall)
            for (int c = 0; c < 3; c++)
                fs[c] *= polyhertz;
        double fssq = dot3(fs, fs); /* squares compared, as in granular.py */
        if (fssq > fn * fn) {
            double fsmag = sqrt(fssq);
            /* at the Coulomb limit: scale the force down, and the spring to
             * what is left of it after the damper */
            double scale = fn / fsmag;
            if (shrsq != 0.0) {
                for (int c = 0; c < 3; c++) {
                    if (wall) {
                        shear[c] = -(fs[c] * scale + damp[c]) / kt;
                    } else {
                        double lag = damp[c] / kt;
                        shear[c] = scale * (shear[c] + lag) - lag;
                    }
                    fs[c] = fs[c] * scale;
                }
            } else {
                fs[0] = fs[1] = fs[2] = 0.0;
            }
        }
    }

    for (int c = 0; c < 3; c++) {
        fel[c] = del[c] * elastic;
        f[c] = del[c] * ccel + fs[c];
    }
    tor[0] = (del[1] * fs[2] - del[2] * fs[1]) * rinv;
    tor[1] = (del[2] * fs[0] - del[0] * fs[2]) * rinv;
    tor[2] = (del[0] * fs[1] - del[1] * fs[0]) * rinv;
    return energy;
}

/* Contacts of the listed sphere pairs (a neighbour list, rows l), with or
 * without friction: `frictional`, `hertz`, `history` and `update` are
 * constants in each call below, so the compiler leaves out what the others
 * need.
 *
 * For each row: r = x_j - x_i + shift (shift_lc NULL: no shifts, an open
 * box), del = -r; touching when
 * |del|^2 < (R_i + R_j)^2.  Touching rows are written to touch_l (their
 * count is returned).  History models read each row's stored shear from
 * shear_lc (left as it is) and write the new shear of every row to
 * new_shear_lc (zero where not touching) and of the touching ones, in their
 * order, to touch_shear_tc.  Forces (f_nc), their dissipative part (all but
 * the normal springs: fd_nc) and torques (t_nc, frictional only) are added
 * to the per-atom arrays, which the caller zeroes.  out[0] += elastic
 * energy, out[1 + 3a + b] += sum of r_a f_b (the virial, if flags[VIRIAL]).
 * The three shear arrays are read or written by history models only (else
 * may be NULL), w_nc and t_nc with friction only, v_nc with friction or
 * gamma_n.  A touching pair at zero distance stops the loop: returns
 * -1 - row. */
static inline __attribute__((always_inline)) int64_t
pairs(int64_t nl, const int64_t *i_l, const int64_t *j_l, const double *shift_lc,
      const double *x_nc, const double *v_nc, const double *w_nc, const double *r_n,
      const double *m_n, const int8_t *hold_n, const double *shear_lc, const double *law,
      const int64_t *flags, double *new_shear_lc, double *touch_shear_tc, double *f_nc,
      double *fd_nc, double *t_nc, int64_t *touch_l, double *out, const int frictional,
      const int hertz, const int history, const int update)
{
    int64_t ntouch = 0;
    double energy = 0.0, w[9] = {0.0}; /* kept in registers, written at the end */
    const int want_virial = (int)flags[VIRIAL];
    const int need_v = frictional || law[GAMMA_N] != 0.0;
    for (int64_t l = 0; l < nl; l++) {
        const int64_t i = i_l[l], j = j_l[l];
        const double *shift = image_shift(shift_lc, l);
        double del[3];
        for (int c = 0; c < 3; c++)
            del[c] = -((x_nc[3 * j + c] - x_nc[3 * i + c]) + shift[c]);
        const double radsum = r_n[i] + r_n[j];
        double *shear = history ? new_shear_lc + 3 * l : NULL;
        if (!(dot3(del, del) < radsum * radsum)) {
            if (history)
                shear[0] = shear[1] = shear[2] = 0.0;
            continue;
        }
        if (dot3(del, del) < DBL_MIN) {  /* coincident, or so close that 1 / r^2 overflows */
            ntouch = -1 - l;
            break;
        }
        touch_l[ntouch++] = l;

        const double ri = r_n[i], rj = r_n[j], mi = m_n[i], mj = m_n[j];
        double meff = mi * mj / (mi + mj);
        if (hold_n) { /* fix freeze: the frozen partner counts as a wall */
            if (hold_n[i])
                meff = mj;
            if (hold_n[j])
                meff = mi;
        }
        double vr[3] = {0.0, 0.0, 0.0}, f[3], fel[3];
        if (need_v)
            for (int c = 0; c < 3; c++)
                vr[c] = v_nc[3 * i + c] - v_nc[3 * j + c];
        if (frictional) {
            double wr[3], tor[3], no_shear[3] = {0.0, 0.0, 0.0};
            for (int c = 0; c < 3; c++)
                wr[c] = ri * w_nc[3 * i + c] + rj * w_nc[3 * j + c];
            if (history) /* the stored shear, which the contact updates */
                for (int c = 0; c < 3; c++)
                    shear[c] = shear_lc[3 * l + c];
            energy += contact(del, radsum, ri * rj / radsum, vr, wr, meff,
                              history ? shear : no_shear, law, flags, hertz, history, update,
                              0, f, fel, tor);
            if (history)
                for (int c = 0; c < 3; c++)
                    touch_shear_tc[3 * (ntouch - 1) + c] = shear[c];
            for (int c = 0; c < 3; c++) {
                t_nc[3 * i + c] += -ri * tor[c];
                t_nc[3 * j + c] += -rj * tor[c];
            }
        } else {
            energy += contact_frictionless(del, radsum, ri * rj / radsum, vr, meff, law,
                                           flags, hertz, f, fel);
        }
        for (int c = 0; c < 3; c++) {
            f_nc[3 * i + c] += f[c];
            f_nc[3 * j + c] -= f[c];
            fd_nc[3 * i + c] += f[c] - fel[c];
            fd_nc[3 * j + c] -= f[c] - fel[c];
        }
        if (want_virial)
            for (int a = 0; a < 3; a++)
                for (int b = 0; b < 3; b++)
                    w[3 * a + b] += -del[a] * f[b];
    }
    out[0] += energy;
    for (int k = 0; k < 9; k++)
        out[1 + k] += w[k];
    return ntouch;
}

/* pairs() with the law's switches as constants (the loop it runs is compiled
 * once for each combination the classic laws use) */
#define PAIRS(FRICTIONAL, HERTZ_, HISTORY_, UPDATE_)                                       \
    pairs(nl, i_l, j_l, shift_lc, x_nc, v_nc, w_nc, r_n, m_n, hold_n, shear_lc, law, flags, \
          new_shear_lc, touch_shear_tc, f_nc, fd_nc, t_nc, touch_l, out, FRICTIONAL, HERTZ_, \
          HISTORY_, UPDATE_)

int64_t granular_pairs(int64_t nl, const int64_t *i_l, const int64_t *j_l,
                       const double *shift_lc, const double *x_nc, const double *v_nc,
                       const double *w_nc, const double *r_n, const double *m_n,
                       const int8_t *hold_n, const double *shear_lc, const double *law,
                       const int64_t *flags, double *new_shear_lc, double *touch_shear_tc,
                       double *f_nc, double *fd_nc, double *t_nc, int64_t *touch_l,
                       double *out)
{
    if (!flags[HISTORY])
        return flags[HERTZ] ? PAIRS(1, 1, 0, 0) : PAIRS(1, 0, 0, 0);
    if (flags[UPDATE])
        return flags[HERTZ] ? PAIRS(1, 1, 1, 1) : PAIRS(1, 0, 1, 1);
    return flags[HERTZ] ? PAIRS(1, 1, 1, 0) : PAIRS(1, 0, 1, 0);
}

int64_t granular_pairs_frictionless(int64_t nl, const int64_t *i_l, const int64_t *j_l,
                                    const double *shift_lc, const double *x_nc,
                                    const double *v_nc, const double *w_nc, const double *r_n,
                                    const double *m_n, const int8_t *hold_n,
                                    const double *shear_lc, const double *law,
                                    const int64_t *flags, double *new_shear_lc,
                                    double *touch_shear_tc, double *f_nc, double *fd_nc,
                                    double *t_nc, int64_t *touch_l, double *out)
{
    return flags[HERTZ] ? PAIRS(0, 1, 0, 0) : PAIRS(0, 0, 0, 0);
}

#undef PAIRS

/* Contacts of every sphere with flat walls: wall w is the plane
 * x[axis_w[w]] = lo_w[w] (spheres above it) and/or x[axis_w[w]] = hi_w[w]
 * (spheres below it), -INFINITY and INFINITY where it has no such side.  A
 * wall is a partner of radius 0 and infinite mass at rest.  Forces are
 * added, wall after wall, to f_nc, their dissipative part (all but the
 * normal springs) to fd_nc and torques (frictional only) to t_nc, which the
 * caller zeroes; the touching spheres are listed in touch_x, wall after
 * wall, and their count is returned.  shear_wnc
 * (history models) holds each wall's stored shear per sphere (nw x n x 3) and
 * receives the new one (zero where not touching); out[0] += elastic energy.
 * Without friction w_nc, shear_wnc and t_nc are not read (may be NULL), nor
 * v_nc when gamma_n is 0.  A sphere centred on a wall stops the loop:
 * returns -1 - (w n + sphere). */
static inline __attribute__((always_inline)) int64_t
walls(int64_t n, int64_t nw, const int64_t *axis_w, const double *lo_w, const double *hi_w,
      const double *x_nc, const double *v_nc, const double *w_nc, const double *r_n,
      const double *m_n, double *shear_wnc, const double *law, const int64_t *flags,
      double *f_nc, double *fd_nc, double *t_nc, int64_t *touch_x, double *out,
      const int frictional)
{
    const int hertz = (int)flags[HERTZ], history = (int)flags[HISTORY];
    const int update = (int)flags[UPDATE], lammps_wall = (int)flags[LAMMPS_WALL];
    int64_t ntouch = 0;
    for (int64_t w = 0; w < nw; w++) {
        const int64_t axis = axis_w[w];
        const double lo = lo_w[w], hi = hi_w[w];
        double *shear_nc = frictional && shear_wnc ? shear_wnc + 3 * n * w : NULL;
        for (int64_t i = 0; i < n; i++) {
            const double x = x_nc[3 * i + axis], rad = r_n[i];
            const double below = x - lo, above = hi - x;
            const double dx = below < above ? below : -above;
            double *shear = shear_nc ? shear_nc + 3 * i : NULL;
            if (!(dx * dx < rad * rad)) {
                if (shear)
                    shear[0] = shear[1] = shear[2] = 0.0;
                continue;
            }
            if (dx == 0.0)
                return -1 - (w * n + i);
            touch_x[ntouch++] = i;
            double del[3] = {0.0, 0.0, 0.0}, f[3], fel[3];
            del[axis] = dx;
            if (frictional) {
                double wr[3], tor[3];
                for (int c = 0; c < 3; c++)
                    wr[c] = rad * w_nc[3 * i + c];
                out[0] += contact(del, rad, rad, v_nc + 3 * i, wr, m_n[i], shear, law, flags,
                                  hertz, history, update, lammps_wall, f, fel, tor);
                for (int c = 0; c < 3; c++)
                    t_nc[3 * i + c] += -rad * tor[c];
            } else {
                out[0] += contact_frictionless(del, rad, rad, v_nc ? v_nc + 3 * i : NULL,
                                               m_n[i], law, flags, hertz, f, fel);
            }
            for (int c = 0; c < 3; c++) {
                f_nc[3 * i + c] += f[c];
                fd_nc[3 * i + c] += f[c] - fel[c];
            }
        }
    }
    return ntouch;
}

int64_t granular_walls(int64_t n, int64_t nw, const int64_t *axis_w, const double *lo_w,
                       const double *hi_w, const double *x_nc, const double *v_nc,
                       const double *w_nc, const double *r_n, const double *m_n,
                       double *shear_wnc, const double *law, const int64_t *flags,
                       double *f_nc, double *fd_nc, double *t_nc, int64_t *touch_x,
                       double *out)
{
    return walls(n, nw, axis_w, lo_w, hi_w, x_nc, v_nc, w_nc, r_n, m_n, shear_wnc, law, flags,
                 f_nc, fd_nc, t_nc, touch_x, out, 1);
}

int64_t granular_walls_frictionless(int64_t n, int64_t nw, const int64_t *axis_w,
                                    const double *lo_w, const double *hi_w,
                                    const double *x_nc, const double *v_nc,
                                    const double *w_nc, const double *r_n, const double *m_n,
                                    double *shear_wnc, const double *law,
                                    const int64_t *flags, double *f_nc, double *fd_nc,
                                    double *t_nc, int64_t *touch_x, double *out)
{
    return walls(n, nw, axis_w, lo_w, hi_w, x_nc, v_nc, w_nc, r_n, m_n, shear_wnc, law, flags,
                 f_nc, fd_nc, t_nc, touch_x, out, 0);
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
