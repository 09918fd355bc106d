/* Compiled bpm/spring kernels: LAMMPS bond_style bpm/spring on a bond set
 * and pair_style bpm/spring on a neighbour list, each in one pass that
 * takes the vectors from the positions, computes the law and adds the
 * forces to the atoms.
 *
 * The same arithmetic as spring_bond_magnitudes, past_eps_c and
 * spring_pair_magnitudes (ase_bpm/laws/spring.py), operation for operation;
 * per-atom sums are accumulated in another order than NumPy's, so results
 * agree to round-off.  Coefficients come per type (bonds) or per type pair
 * (pairs), not per bond.
 */

#include "bonds.h"

/* a bond type's coefficients, in this order (the bond_coeff line) */
enum { SPRING_K, SPRING_EPS_C, SPRING_GAMMA, SPRING_NCOEFF };
/* switches of spring_bonds, in this order, in the `flags` array */
enum { SMOOTH, NORMALIZE, BREAKING, VIRIAL, NFLAGS_SPRING };
/* what spring_bonds and spring_pairs sum, in this order, in `out` */
enum { OUT_ENERGY, OUT_RELEASED, OUT_VIRIAL, NOUT = OUT_VIRIAL + 9 };

/* bond_style bpm/spring on the bonds `select` (NULL: all nb bonds).
 *
 * r0_b: reference lengths; a NaN one is taken now (the length is written
 * there).  coeff_t: SPRING_NCOEFF per bond type.  v_nc NULL: undamped.
 * With flags[BREAKING], a bond past eps_c gets broken_b[b] = 1, gives no
 * force, and its energy counts as released.  Adds the forces to f_nc and
 * their damping part to fd_nc (if not NULL); sums the energy of the bonds
 * that stay, the released energy and (flags[VIRIAL]) the virial into out.
 * Returns the number of bonds that break. */
int64_t spring_bonds(int64_t nb, const int64_t *restrict select, const int64_t *restrict i_b,
                     const int64_t *restrict j_b, const int64_t *restrict type_b,
                     const double *restrict x_nc, const double *restrict v_nc,
                     const double *restrict box, double *restrict r0_b,
                     const double *restrict coeff_t, const int64_t *restrict flags,
                     double *restrict f_nc, double *restrict fd_nc,
                     int8_t *restrict broken_b, double *restrict out)
{
    const int smooth = (int)flags[SMOOTH], normalize = (int)flags[NORMALIZE];
    const int breaking = (int)flags[BREAKING], want_virial = (int)flags[VIRIAL];
    int64_t nbroken = 0;
    double kept = 0.0, released = 0.0;
    for (int64_t s = 0; s < nb; s++) {
        const int64_t b = select ? select[s] : s;
        const int64_t i = i_b[b], j = j_b[b];
        const double *c = coeff_t + SPRING_NCOEFF * type_b[b];
        double r[3];
        const double len = bond_vector(x_nc, i, j, box, r);
        if (isnan(r0_b[b]))
            r0_b[b] = len;
        const double r0 = r0_b[b];
        const double rinv = len > 0.0 ? 1.0 / len : 0.0;
        const double e = (len - r0) / r0;
        double f = c[SPRING_K] * (normalize ? e : len - r0);
        double energy = 0.5 * e * e, w = 1.0;
        if (smooth) {
            double x2 = e / c[SPRING_EPS_C];
            x2 *= x2;
            double x8 = x2 * x2;
            x8 *= x8;
            w = 1.0 - x8;
            f *= w;
            energy -= 0.1 * e * e * x8;
        }
        energy *= c[SPRING_K] * (normalize ? r0 : r0 * r0);
        if (breaking && fabs(len - r0) > c[SPRING_EPS_C] * r0) {
            broken_b[b] = 1;
            nbroken++;
            released += energy;
            continue;  /* as LAMMPS: a bond that breaks gives no force */
        }
        kept += energy;
        if (v_nc) {
            double fd = c[SPRING_GAMMA] * rinv * relative_speed(v_nc, i, j, r);
            if (smooth)
                fd *= w;
            f += fd;
            if (fd_nc)
                add_pair(fd_nc, i, j, r, fd * rinv);
        }
        add_pair(f_nc, i, j, r, f * rinv);
        if (want_virial)
            add_virial(out + OUT_VIRIAL, r, f * rinv);
    }
    out[OUT_ENERGY] += kept;
    out[OUT_RELEASED] += released;
    return nbroken;
}

/* a type pair's coefficients, in this order (the pair_coeff line) */
enum { PAIR_K, PAIR_R_C, PAIR_GAMMA, PAIR_NCOEFF };

/* pair_style bpm/spring on the listed pairs `select` (NULL: all np) of a
 * neighbour list: r = x[j] - x[i] + shift; those closer than r_c repel.
 * coeff_tt: PAIR_NCOEFF per type pair, ntypes x ntypes.  v_nc NULL:
 * undamped.  Adds to f_nc, fd_nc (if not NULL) and out (energy, virial
 * with want_virial).  Returns the number of pairs in contact. */
int64_t spring_pairs(int64_t np, const int64_t *select, const int64_t *i_p,
                     const int64_t *j_p, const double *shift_pc, const int64_t *types_n,
                     int64_t ntypes, const double *x_nc, const double *v_nc,
                     const double *coeff_tt, int64_t want_virial, double *f_nc,
                     double *fd_nc, double *out)
{
    int64_t ntouch = 0;
    for (int64_t s = 0; s < np; s++) {
        const int64_t p = select ? select[s] : s;
        const int64_t i = i_p[p], j = j_p[p];
        const double *c = coeff_tt + PAIR_NCOEFF * (types_n[i] * ntypes + types_n[j]);
        double r[3];
        for (int k = 0; k < 3; k++)
            r[k] = x_nc[3 * j + k] - x_nc[3 * i + k] + shift_pc[3 * p + k];
        const double rsq = dot(r, r), rc = c[PAIR_R_C];
        if (!(rsq < rc * rc))
            continue;
        ntouch++;
        const double len = sqrt(rsq);
        const double rinv = len > 0.0 ? 1.0 / len : 0.0;
        const double overlap = rc - len;
        double f = -c[PAIR_K] * overlap;
        out[OUT_ENERGY] += 0.5 * c[PAIR_K] * overlap * overlap;
        if (v_nc) {
            const double x = len / rc, x2 = x * x, x4 = x2 * x2;
            const double fd = c[PAIR_GAMMA] * (1.0 - x4 * x4) * rinv
                              * relative_speed(v_nc, i, j, r);
            f = f + fd;
            if (fd_nc)
                add_pair(fd_nc, i, j, r, fd * rinv);
        }
        add_pair(f_nc, i, j, r, f * rinv);
        if (want_virial)
            add_virial(out + OUT_VIRIAL, r, f * rinv);
    }
    return ntouch;
}
