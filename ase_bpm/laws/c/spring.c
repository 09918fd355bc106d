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

/* Bonds go through spring_bonds in blocks of BLOCK: one pass gathers what
 * each bond needs (its vector, reference length, coefficients and relative
 * speed), a second computes the law over the block lane by lane without a
 * branch, so that the compiler runs several bonds per vector instruction
 * (the square roots and divisions are most of the work), and a third adds
 * the forces to the atoms in the order of the bonds.  IEEE arithmetic is the
 * same in vector lanes: the results are those of one bond at a time. */
#define BLOCK 64

/* What every spring law's lane starts with: the bond's length, its
 * reference length (a NaN one becomes the length), the inverse length (0
 * for a zero length) and the strain. */
struct lane {
    double len, r0, rinv, e;
};

static inline struct lane lane_start(double rsq, double r0_given)
{
    struct lane l;
    l.len = sqrt(rsq);
    l.r0 = isnan(r0_given) ? l.len : r0_given;
    const double inverse = 1.0 / l.len;
    l.rinv = l.len > 0.0 ? inverse : 0.0;
    l.e = (l.len - l.r0) / l.r0;
    return l;
}

/* ... and ends with: whether it breaks (past eps_c, with `breaking`), its
 * damping force (gamma, smoothed by w) and the elastic force f, both per
 * unit of bond vector, and its energy, into lane k of the outputs. */
static inline void lane_end(int64_t k, struct lane l, int breaking, double epsc,
                            double gamma, double vr, double f, double w, double energy,
                            double *restrict s_k, double *restrict sd_k,
                            double *restrict energy_k, double *restrict gone_k)
{
    gone_k[k] = fabs(l.len - l.r0) > epsc * l.r0 ? (double)breaking : 0.0;
    const double fd = gamma * l.rinv * vr * w;
    s_k[k] = (f + fd) * l.rinv;
    sd_k[k] = fd * l.rinv;
    energy_k[k] = energy;
}

/* The law on n gathered bonds: rsq_k their squared lengths, r0_k their
 * reference lengths (a NaN one becomes the length), k_k, epsc_k and gamma_k
 * their coefficients, vr_k the relative speed along the bond vector (0
 * undamped), volume_k (with `volume`) the volumetric force of volume/factor
 * (volumetric_force).  Gives the force on i per unit of bond vector s_k and its
 * damping part sd_k, the bond's energy, and gone_k 1 where a bond breaks
 * (with `breaking`).  Branch-free so that it vectorizes. */
VECTOR_CLONES static void spring_law(int64_t n, int smooth, int normalize, int breaking,
                                     int volume, const double *restrict rsq_k,
                                     double *restrict r0_k, const double *restrict k_k,
                                     const double *restrict epsc_k,
                                     const double *restrict gamma_k,
                                     const double *restrict volume_k,
                                     const double *restrict vr_k, double *restrict s_k,
                                     double *restrict sd_k, double *restrict energy_k,
                                     double *restrict gone_k)
{
    for (int64_t k = 0; k < n; k++) {
        const struct lane l = lane_start(rsq_k[k], r0_k[k]);
        const double e = l.e, r0 = l.r0;
        r0_k[k] = r0;
        double x2 = e / epsc_k[k];
        x2 *= x2;
        double x8 = x2 * x2;
        x8 *= x8;
        /* (f in two statements: written as one, GCC 12 leaves the loop scalar) */
        double f = k_k[k] * (normalize ? e : l.len - r0);
        f += volume ? volume_k[k] : 0.0;  /* (f is never -0: adding 0 leaves it) */
        const double w = smooth ? 1.0 - x8 : 1.0;
        f *= w;
        double energy = 0.5 * e * e - (smooth ? 0.1 * e * e * x8 : 0.0);
        energy *= k_k[k] * (normalize ? r0 : r0 * r0);
        lane_end(k, l, breaking, epsc_k[k], gamma_k[k], vr_k[k], f, w, energy, s_k, sd_k,
                 energy_k, gone_k);
    }
}

/* a bpm/spring/plastic bond type's coefficients, in this order */
enum { PLASTIC_K, PLASTIC_EPS_C, PLASTIC_GAMMA, PLASTIC_EPS_P, PLASTIC_NCOEFF };

/* x^8 by three squarings, as eighth_power (ase_bpm/laws/spring.py) */
static inline double eighth_power(double x)
{
    const double x2 = x * x, x4 = x2 * x2;
    return x4 * x4;
}

/* bond_style bpm/spring/plastic on n gathered bonds, as spring_law, with
 * epsp_k their yield strains and ep_k their plastic strains of the last
 * step (0 where none), which become those the bonds reach now: the
 * arithmetic of plastic_strain and plastic_bond_magnitudes. */
VECTOR_CLONES static void plastic_law(int64_t n, int smooth, int normalize, int breaking,
                                      const double *restrict rsq_k, double *restrict r0_k,
                                      const double *restrict k_k,
                                      const double *restrict epsc_k,
                                      const double *restrict gamma_k,
                                      const double *restrict epsp_k, double *restrict ep_k,
                                      const double *restrict vr_k, double *restrict s_k,
                                      double *restrict sd_k, double *restrict energy_k,
                                      double *restrict gone_k)
{
    for (int64_t k = 0; k < n; k++) {
        const struct lane l = lane_start(rsq_k[k], r0_k[k]);
        const double e = l.e, r0 = l.r0;
        r0_k[k] = r0;
        const double last = ep_k[k], epsp = epsp_k[k];
        const double yielded = e > last + epsp ? e - epsp : last;
        const double ep = e < yielded - epsp ? e + epsp : yielded;
        ep_k[k] = ep;
        const double elastic = e - ep;
        double f = k_k[k] * (normalize ? elastic : l.len - (1.0 + ep) * r0);
        const double w = smooth ? 1.0 - eighth_power(e / epsc_k[k]) : 1.0;
        f *= w;
        const double e9 = eighth_power(e) * e, ep9 = eighth_power(ep) * ep;
        double energy = 0.5 * elastic * elastic
                        - (smooth ? (0.1 * (e9 * e - ep9 * ep) - ep * (e9 - ep9) / 9.0)
                                        / eighth_power(epsc_k[k])
                                  : 0.0);
        energy *= k_k[k] * (normalize ? r0 : r0 * r0);
        lane_end(k, l, breaking, epsc_k[k], gamma_k[k], vr_k[k], f, w, energy, s_k, sd_k,
                 energy_k, gone_k);
    }
}

/* spring_bonds' (and plastic_bonds') inputs and per-bond outputs, for
 * spring_bond_range; ep_b NULL: bpm/spring, else bpm/spring/plastic with
 * the plastic strains ep_b of the last step (per bond of the set, NaN: none
 * yet) and ep_out the strains reached now (per bond of the selection) */
struct spring_bond_args {
    const int64_t *select, *i_b, *j_b, *type_b;
    const double *x_nc, *v_nc, *box, *coeff_t, *ep_b;
    double *r0_b, *ep_out;
    int8_t *broken_b;
    int smooth, normalize, breaking, want_virial;
    /* volume/factor (vol_n not NULL): the atoms' volumes now and in the
     * reference state (bond_volumes); coeff_t then holds a_v fourth */
    const double *vol_n, *vol0_n;
};

/* a bpm/spring bond type's a_v with volume/factor, after its coefficients */
enum { SPRING_A_V = SPRING_NCOEFF, VOLUME_NCOEFF };
/* the exponent of the volume ratio (VOLUME_EXPONENT) */
static const double VOLUME_EXPONENT = 1.0 / 3.0;

/* spring_bonds on the bonds [start, end) of the selection, adding to these
 * f_nc, fd_nc and out (a chunk_kernel, bonds.h) */
static int64_t spring_bond_range(const void *args, int64_t start, int64_t end,
                                 double *restrict f_nc, double *restrict fd_nc,
                                 double *restrict out)
{
    const struct spring_bond_args *a = args;
    const int64_t *restrict select = a->select, *restrict i_b = a->i_b;
    const int64_t *restrict j_b = a->j_b, *restrict type_b = a->type_b;
    const double *restrict x_nc = a->x_nc, *restrict v_nc = a->v_nc;
    const double *restrict box = a->box, *restrict coeff_t = a->coeff_t;
    double *restrict r0_b = a->r0_b;
    int8_t *restrict broken_b = a->broken_b;
    int64_t nbroken = 0;
    double kept = 0.0, released = 0.0;
    double r_kc[BLOCK][3], rsq_k[BLOCK], r0_k[BLOCK], k_k[BLOCK], epsc_k[BLOCK];
    double gamma_k[BLOCK], vr_k[BLOCK], s_k[BLOCK], sd_k[BLOCK], energy_k[BLOCK];
    double gone_k[BLOCK], epsp_k[BLOCK], ep_k[BLOCK], volume_k[BLOCK];
    const double *restrict ep_b = a->ep_b;
    const double *restrict vol_n = a->vol_n, *restrict vol0_n = a->vol0_n;
    const int64_t ncoeff = ep_b ? PLASTIC_NCOEFF : vol_n ? VOLUME_NCOEFF : SPRING_NCOEFF;
    for (int64_t first = start; first < end; first += BLOCK) {
        const int64_t n = end - first < BLOCK ? end - first : BLOCK;
        for (int64_t k = 0; k < n; k++) {  /* gather */
            const int64_t b = select ? select[first + k] : first + k;
            const int64_t i = i_b[b], j = j_b[b];
            const double *c = coeff_t + ncoeff * type_b[b];
            rsq_k[k] = bond_vector_squared(x_nc, i, j, box, r_kc[k]);
            r0_k[k] = r0_b[b];
            k_k[k] = c[SPRING_K];
            epsc_k[k] = c[SPRING_EPS_C];
            gamma_k[k] = c[SPRING_GAMMA];
            vr_k[k] = v_nc ? relative_speed(v_nc, i, j, r_kc[k]) : 0.0;
            if (ep_b) {
                epsp_k[k] = c[PLASTIC_EPS_P];
                ep_k[k] = isnan(ep_b[b]) ? 0.0 : ep_b[b];
            }
            if (vol_n) {  /* (as volume_ratios and volumetric_force) */
                const double len = sqrt(rsq_k[k]);
                const double r0 = isnan(r0_k[k]) ? len : r0_k[k];
                const double ratio = (vol_n[i] + vol_n[j]) / (vol0_n[i] + vol0_n[j]);
                volume_k[k] = -c[SPRING_A_V]
                              * ((pow(ratio, VOLUME_EXPONENT) - 1.0) - (len - r0) / r0);
            }
        }
        if (ep_b)
            plastic_law(n, a->smooth, a->normalize, a->breaking, rsq_k, r0_k, k_k, epsc_k,
                        gamma_k, epsp_k, ep_k, vr_k, s_k, sd_k, energy_k, gone_k);
        else
            spring_law(n, a->smooth, a->normalize, a->breaking, vol_n != NULL, rsq_k, r0_k,
                       k_k, epsc_k, gamma_k, volume_k, vr_k, s_k, sd_k, energy_k, gone_k);
        for (int64_t k = 0; k < n; k++) {  /* scatter, in the order of the bonds */
            const int64_t b = select ? select[first + k] : first + k;
            if (ep_b)  /* (a bond broken earlier keeps what it had) */
                a->ep_out[first + k] = type_b[b] == 0 ? ep_b[b] : ep_k[k];
            if (type_b[b] == 0)
                continue;  /* broken earlier, still listed: its lane is not used */
            if (isnan(r0_b[b]))
                r0_b[b] = r0_k[k];
            if (gone_k[k] != 0.0) {
                broken_b[b] = 1;
                nbroken++;
                released += energy_k[k];
                continue;  /* as LAMMPS: a bond that breaks gives no force */
            }
            kept += energy_k[k];
            const int64_t i = i_b[b], j = j_b[b];
            if (fd_nc && v_nc)
                add_pair(fd_nc, i, j, r_kc[k], sd_k[k]);
            add_pair(f_nc, i, j, r_kc[k], s_k[k]);
            if (a->want_virial)
                add_virial(out + OUT_VIRIAL, r_kc[k], s_k[k]);
        }
    }
    out[OUT_ENERGY] += kept;
    out[OUT_RELEASED] += released;
    return nbroken;
}

/* spring_bond_range on the bonds `select` of the set (the entry points
 * below, with their kind's arguments: ep_b and ep_out for bpm/spring/plastic,
 * vol_n and vol0_n for volume/factor, NULL otherwise) */
static int64_t run_spring_bonds(int64_t nb, const int64_t *select, const int64_t *i_b,
                                const int64_t *j_b, const int64_t *type_b,
                                const double *x_nc, const double *v_nc, const double *box,
                                double *r0_b, const double *coeff_t, const int64_t *flags,
                                const double *ep_b, double *ep_out, const double *vol_n,
                                const double *vol0_n, double *f_nc, double *fd_nc,
                                int8_t *broken_b, double *out, int64_t natoms,
                                int64_t threads)
{
    const struct spring_bond_args args = {
        select, i_b, j_b, type_b, x_nc, v_nc, box, coeff_t, ep_b, r0_b, ep_out, broken_b,
        (int)flags[SMOOTH], (int)flags[NORMALIZE], (int)flags[BREAKING], (int)flags[VIRIAL],
        vol_n, vol0_n};
    return run_in_chunks(spring_bond_range, &args, nb, threads, natoms, f_nc,
                         v_nc ? fd_nc : NULL, NOUT, out);
}

/* bond_style bpm/spring on the bonds `select` (NULL: all nb bonds).
 *
 * r0_b: reference lengths; a NaN one is taken now (the length is written
 * there).  coeff_t: SPRING_NCOEFF per bond type; a bond of type 0 (broken
 * earlier, still listed) is passed over.  v_nc NULL: undamped.
 * With flags[BREAKING], a bond past eps_c gets broken_b[b] = 1, gives no
 * force, and its energy counts as released.  Adds the forces to f_nc and
 * their damping part to fd_nc (if not NULL; natoms rows each); sums the
 * energy of the bonds that stay, the released energy and (flags[VIRIAL]) the
 * virial into out.  On `threads` threads where built with OpenMP
 * (run_in_chunks, bonds.h; 1: serially).  Returns the number of bonds that
 * break, or -1 out of memory for the threads' buffers. */
int64_t spring_bonds(int64_t nb, const int64_t *select, const int64_t *i_b,
                     const int64_t *j_b, const int64_t *type_b, const double *x_nc,
                     const double *v_nc, const double *box, double *r0_b,
                     const double *coeff_t, const int64_t *flags, double *f_nc,
                     double *fd_nc, int8_t *broken_b, double *out, int64_t natoms,
                     int64_t threads)
{
    return run_spring_bonds(nb, select, i_b, j_b, type_b, x_nc, v_nc, box, r0_b, coeff_t,
                            flags, NULL, NULL, NULL, NULL, f_nc, fd_nc, broken_b, out, natoms,
                            threads);
}

/* bond_style bpm/spring volume/factor yes on the bonds `select`, as
 * spring_bonds: coeff_t holds VOLUME_NCOEFF per bond type (a_v fourth);
 * vol_n and vol0_n the atoms' volumes of bond_volumes. */
int64_t spring_volume_bonds(int64_t nb, const int64_t *select, const int64_t *i_b,
                            const int64_t *j_b, const int64_t *type_b, const double *x_nc,
                            const double *v_nc, const double *box, double *r0_b,
                            const double *coeff_t, const int64_t *flags,
                            const double *vol_n, const double *vol0_n, double *f_nc,
                            double *fd_nc, int8_t *broken_b, double *out, int64_t natoms,
                            int64_t threads)
{
    return run_spring_bonds(nb, select, i_b, j_b, type_b, x_nc, v_nc, box, r0_b, coeff_t,
                            flags, NULL, NULL, vol_n, vol0_n, f_nc, fd_nc, broken_b, out,
                            natoms, threads);
}

/* volume/factor's volume of each atom (bond_volumes): vol_n the sum of the
 * cubed lengths of its intact bonds (type > 0) among all nb of the set,
 * vol0_n of their reference lengths (a NaN one: the length now); both
 * natoms long, zeroed here. */
void bond_volumes(int64_t nb, const int64_t *i_b, const int64_t *j_b,
                  const int64_t *type_b, const double *x_nc, const double *box,
                  const double *r0_b, double *vol_n, double *vol0_n, int64_t natoms)
{
    for (int64_t n = 0; n < natoms; n++)
        vol_n[n] = vol0_n[n] = 0.0;
    for (int64_t b = 0; b < nb; b++) {
        if (type_b[b] <= 0)
            continue;
        double r[3];
        const double len = sqrt(bond_vector_squared(x_nc, i_b[b], j_b[b], box, r));
        const double r0 = isnan(r0_b[b]) ? len : r0_b[b];
        const double cube = len * len * len, cube0 = r0 * r0 * r0;
        vol_n[i_b[b]] += cube;
        vol_n[j_b[b]] += cube;
        vol0_n[i_b[b]] += cube0;
        vol0_n[j_b[b]] += cube0;
    }
}

/* bond_style bpm/spring/plastic on the bonds `select`, as spring_bonds:
 * coeff_t holds PLASTIC_NCOEFF per bond type; ep_b the plastic strain of
 * each bond of the set as of the last step (NaN: none yet, 0); ep_out gets
 * the strain each bond of the selection reaches now (in the order of the
 * selection; a bond of type 0 keeps its own). */
int64_t plastic_bonds(int64_t nb, const int64_t *select, const int64_t *i_b,
                      const int64_t *j_b, const int64_t *type_b, const double *x_nc,
                      const double *v_nc, const double *box, double *r0_b,
                      const double *coeff_t, const int64_t *flags, const double *ep_b,
                      double *ep_out, double *f_nc, double *fd_nc, int8_t *broken_b,
                      double *out, int64_t natoms, int64_t threads)
{
    return run_spring_bonds(nb, select, i_b, j_b, type_b, x_nc, v_nc, box, r0_b, coeff_t,
                            flags, ep_b, ep_out, NULL, NULL, f_nc, fd_nc, broken_b, out,
                            natoms, threads);
}

/* a type pair's coefficients, in this order (the pair_coeff line); k_a
 * with anharmonic yes only */
enum { PAIR_K, PAIR_R_C, PAIR_GAMMA, PAIR_NCOEFF, PAIR_K_A = PAIR_NCOEFF,
       ANHARMONIC_NCOEFF };

/* spring_pairs' inputs, for spring_pair_range (ncoeff: PAIR_NCOEFF, or
 * ANHARMONIC_NCOEFF with anharmonic yes) */
struct spring_pair_args {
    const int64_t *select, *i_p, *j_p, *types_n;
    const double *shift_pc, *x_nc, *v_nc, *coeff_tt;
    int64_t ntypes, ncoeff, want_virial;
};

/* spring_pairs on the pairs [start, end) of the selection, adding to these
 * f_nc, fd_nc and out (a chunk_kernel, bonds.h) */
static int64_t spring_pair_range(const void *args, int64_t start, int64_t end,
                                 double *f_nc, double *fd_nc, double *out)
{
    const struct spring_pair_args *a = args;
    int64_t ntouch = 0;
    for (int64_t s = start; s < end; s++) {
        const int64_t p = a->select ? a->select[s] : s;
        const int64_t i = a->i_p[p], j = a->j_p[p];
        const double *c = a->coeff_tt
                          + a->ncoeff * (a->types_n[i] * a->ntypes + a->types_n[j]);
        const double *shift = image_shift(a->shift_pc, p);
        double r[3];
        for (int k = 0; k < 3; k++)
            r[k] = a->x_nc[3 * j + k] - a->x_nc[3 * i + k] + shift[k];
        const double rsq = dot(r, r), rc = c[PAIR_R_C];
        if (!(rsq < rc * rc))
            continue;
        ntouch++;
        const double len = sqrt(rsq);
        const double rinv = len > 0.0 ? 1.0 / len : 0.0;
        const double overlap = rc - len;
        double f = -c[PAIR_K] * overlap;
        out[OUT_ENERGY] += 0.5 * c[PAIR_K] * overlap * overlap;
        if (a->v_nc) {
            const double x = len / rc, x2 = x * x, x4 = x2 * x2;
            const double fd = c[PAIR_GAMMA] * (1.0 - x4 * x4) * rinv
                              * relative_speed(a->v_nc, i, j, r);
            f = f + fd;
            if (fd_nc)
                add_pair(fd_nc, i, j, r, fd * rinv);
        }
        if (a->ncoeff == ANHARMONIC_NCOEFF) {  /* (as anharmonic_pair_magnitudes) */
            const double overlap2 = overlap * overlap, k_a = c[PAIR_K_A];
            f = f - k_a * overlap2 * overlap;
            out[OUT_ENERGY] += 0.25 * k_a * overlap2 * overlap2;
        }
        add_pair(f_nc, i, j, r, f * rinv);
        if (a->want_virial)
            add_virial(out + OUT_VIRIAL, r, f * rinv);
    }
    return ntouch;
}

/* pair_style bpm/spring on the listed pairs `select` (NULL: all np) of a
 * neighbour list: r = x[j] - x[i] + shift (shift_pc NULL: no shifts, an
 * open box); those closer than r_c repel.
 * coeff_tt: ncoeff per type pair, ntypes x ntypes: PAIR_NCOEFF, or
 * ANHARMONIC_NCOEFF for anharmonic yes (k_a fourth).  v_nc NULL:
 * undamped.  Adds to f_nc, fd_nc (if not NULL; natoms rows each) and out
 * (energy, virial with want_virial).  On `threads` threads as spring_bonds.
 * Returns the number of pairs in contact, or -1 out of memory for the
 * threads' buffers. */
int64_t spring_pairs(int64_t np, const int64_t *select, const int64_t *i_p,
                     const int64_t *j_p, const double *shift_pc, const int64_t *types_n,
                     int64_t ntypes, const double *x_nc, const double *v_nc,
                     const double *coeff_tt, int64_t ncoeff, int64_t want_virial,
                     double *f_nc, double *fd_nc, double *out, int64_t natoms,
                     int64_t threads)
{
    const struct spring_pair_args args = {select, i_p, j_p, types_n, shift_pc, x_nc,
                                          v_nc, coeff_tt, ntypes, ncoeff, want_virial};
    return run_in_chunks(spring_pair_range, &args, np, threads, natoms, f_nc,
                         v_nc ? fd_nc : NULL, NOUT, out);
}
