/* Compiled bond_style bpm/rotational: forces and torques of bonds that
 * resist stretching, shearing, bending and twisting, between particles that
 * carry an orientation, in one pass over the bonds that takes the vectors
 * from the positions, computes the law and adds forces and torques to the
 * atoms.
 *
 * The same arithmetic as rotational_bonds, rotational_damping and
 * RotationalBond.forces (ase_bpm/laws/rotational.py), operation for
 * operation, and as ase_bpm/core/quaternions.py for the quaternions; acos
 * is the C library's, per-atom sums are accumulated in another order than
 * NumPy's, so results agree to round-off.  Coefficients come per bond type.
 *
 * As there, LAMMPS's particle 1 of a bond is the end with the smaller atom
 * index, the bond vector is r = x_1 - x_2 and the reference direction points
 * the same way; the kernel reads and writes the reference direction along
 * the bond as listed (from its first atom to its second).
 */

#include "bonds.h"

/* a bond type's coefficients, in this order (the bond_coeff line of the
 * reference build, RotationalBond.coefficients) */
enum {
    ROT_K_R, ROT_K_S, ROT_K_T, ROT_K_B, ROT_F_RC, ROT_F_SC, ROT_TAU_TC, ROT_TAU_BC,
    ROT_GAMMA_N, ROT_GAMMA_S, ROT_GAMMA_R, ROT_GAMMA_T, ROT_NCOEFF
};

/* numbers of a bond's reference state (struct rotational_bonds' dir_bc) */
#define REF_WIDTH 4

/* sqrt(2) / 2, in the components of the quaternion that turns z onto the bond */
static const double HALF_SQRT2 = 0.70710678118654757; /* 0.5 * sqrt(2.0), rounded */

/* -- vectors and quaternions ((w, i, j, k), LAMMPS's order) -------------------- */

static inline void cross(const double *a, const double *b, double *out)
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* v over its length; a zero vector stays zero (LAMMPS norm3) */
static inline void unit(const double *v, double *out)
{
    const double length2 = dot(v, v);
    const double scale = length2 > 0.0 ? 1.0 / sqrt(length2) : 0.0;
    for (int c = 0; c < 3; c++)
        out[c] = v[c] * scale;
}

static inline double clipped_acos(double c)
{
    return acos(c < -1.0 ? -1.0 : (c > 1.0 ? 1.0 : c));
}

static inline void conjugate(const double *q, double *out)
{
    out[0] = q[0];
    out[1] = -q[1];
    out[2] = -q[2];
    out[3] = -q[3];
}

/* a b */
static inline void multiply(const double *a, const double *b, double *out)
{
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    out[1] = a[0] * b[1] + b[0] * a[1] + a[2] * b[3] - a[3] * b[2];
    out[2] = a[0] * b[2] + b[0] * a[2] + a[3] * b[1] - a[1] * b[3];
    out[3] = a[0] * b[3] + b[0] * a[3] + a[1] * b[2] - a[2] * b[1];
}

/* q v q*: v turned by the unit quaternion q */
static inline void rotate(const double *q, const double *v, double *out)
{
    const double t0 = -q[1] * v[0] - q[2] * v[1] - q[3] * v[2]; /* q (0, v) */
    const double t1 = q[0] * v[0] + q[2] * v[2] - q[3] * v[1];
    const double t2 = q[0] * v[1] + q[3] * v[0] - q[1] * v[2];
    const double t3 = q[0] * v[2] + q[1] * v[1] - q[2] * v[0];
    out[0] = -q[1] * t0 + q[0] * t1 - q[3] * t2 + q[2] * t3; /* (q (0, v)) q* */
    out[1] = -q[2] * t0 + q[3] * t1 + q[0] * t2 - q[1] * t3;
    out[2] = -q[3] * t0 - q[2] * t1 + q[1] * t2 + q[0] * t3;
}

static inline double length(const double *v) { return sqrt(dot(v, v)); }

/* -- the law on one bond, in LAMMPS's convention ------------------------------ */

/* One bond's forces and torques before breaking and smoothing, as LAMMPS
 * names them (RotationalForces, ase_bpm/laws/rotational.py). */
struct rotational_out {
    double f12[3];   /* force on particle 2 from particle 1, with damping */
    double fd12[3];  /* its damping part */
    double t12[3];   /* torque on particle 2, with damping */
    double t21[3];   /* torque on particle 1, with damping */
    double td12[3];  /* the damping parts of the two torques */
    double td21[3];
    double breaking; /* B, the breaking measure (>= 0) */
};

/* The damping force on particle 2 and torques on 2 and 1 (rotational_damping):
 * normal and sliding velocities, rolling and twisting angular velocities,
 * each against its coefficient; r = x_1 - x_2, v12 = v_1 - v_2. */
static void rotational_damping(const double *r, double rinv, const double *coeff,
                               const double *v12, const double *w1, const double *w2,
                               struct rotational_out *o)
{
    double rhat[3], vn12[3], half_vt21[3], s1[3], s2[3], slide[3], t_slide[3];
    double w1r[3], w2r[3], w1n[3], w2n[3], rolled[3], roll[3];
    for (int c = 0; c < 3; c++)
        rhat[c] = r[c] * rinv;
    const double vn = dot(v12, rhat); /* (v_1 - v_2) . n */
    for (int c = 0; c < 3; c++) {
        vn12[c] = rhat[c] * vn;
        half_vt21[c] = 0.5 * ((-v12[c]) - (-vn12[c])); /* (v_t2 - v_t1) / 2 */
    }
    cross(w1, r, w1r);
    cross(w2, r, w2r);
    for (int c = 0; c < 3; c++) {
        s1[c] = -0.5 * w1r[c] - half_vt21[c];
        s2[c] = 0.5 * w2r[c] + half_vt21[c];
        slide[c] = (s1[c] - s2[c]) * coeff[ROT_GAMMA_S];
        o->fd12[c] = vn12[c] * coeff[ROT_GAMMA_N] + slide[c];
    }
    cross(r, slide, t_slide);
    cross(w1, rhat, w1n);
    cross(w2, rhat, w2n);
    for (int c = 0; c < 3; c++)
        rolled[c] = w1n[c] - w2n[c];
    cross(r, rolled, roll);
    const double half_gamma_r = 0.5 * coeff[ROT_GAMMA_R];
    const double half_gamma_t = 0.5 * coeff[ROT_GAMMA_T];
    const double w1_along = dot(w1, rhat), w2_along = dot(w2, rhat);
    for (int c = 0; c < 3; c++) {
        const double slide_torque = 0.5 * t_slide[c];
        const double rolling = roll[c] * half_gamma_r;
        const double twisting = (rhat[c] * w1_along - rhat[c] * w2_along) * half_gamma_t;
        o->td12[c] = slide_torque + rolling + twisting;
        o->td21[c] = slide_torque - rolling - twisting;
    }
}

/* The forces and torques of one bond (rotational_bonds): r = x_1 - x_2, r0
 * and dir0 the reference length and unit direction (same sense), q1 and q2
 * the two orientations, coeff the bond type's coefficients; v12 = v_1 - v_2,
 * w1, w2 the angular velocities, or v12 NULL undamped. */
static void rotational_bond(const double *r, double r0, const double *dir0, const double *q1,
                            const double *q2, const double *coeff, int normalize,
                            const double *v12, const double *w1, const double *w2,
                            struct rotational_out *o)
{
    const double len = sqrt(dot(r, r));
    const double rinv = 1.0 / len, r0inv = 1.0 / r0;
    double kr = coeff[ROT_K_R], ks = coeff[ROT_K_S];
    if (normalize) {
        kr = kr * r0inv;
        ks = ks * r0inv;
    }
    double r0v[3];
    for (int c = 0; c < 3; c++)
        r0v[c] = dir0[c] * r0;

    /* stretching and shear, in particle 2's frame */
    double q2inv[4], rb[3], f_rot[3], inner[3], outer[3], s[3], tdir[3], fs[3], ts[3];
    conjugate(q2, q2inv);
    rotate(q2inv, r, rb);
    const double fr = kr * (len - r0);
    const double fr_per_r = fr * rinv;
    for (int c = 0; c < 3; c++)
        f_rot[c] = rb[c] * fr_per_r;
    const double gamma = clipped_acos(dot(r0v, rb) * rinv * r0inv);
    cross(rb, r0v, inner);
    cross(rb, inner, outer);
    unit(outer, s);
    const double shear = ks * len * gamma;
    cross(r0v, rb, inner);
    unit(inner, tdir);
    const double shear_torque = 0.5 * len * ks * len * gamma;
    for (int c = 0; c < 3; c++) {
        fs[c] = s[c] * shear;
        ts[c] = tdir[c] * shear_torque;
    }

    /* the quaternion turning z onto the bond (Wang and Mora's X'Y'Z' rotations) */
    double mq[4];
    const double up = len + rb[2], down = len - rb[2];
    mq[0] = HALF_SQRT2 * sqrt((up < 0.0 ? 0.0 : up) * rinv);
    const double in_xy = sqrt(rb[0] * rb[0] + rb[1] * rb[1]);
    double m1 = in_xy != 0.0 ? -HALF_SQRT2 / in_xy : 0.0; /* (along z: no x, y terms) */
    m1 *= sqrt((down < 0.0 ? 0.0 : down) * rinv);
    mq[1] = m1 * rb[1];
    mq[2] = -m1 * rb[0];
    mq[3] = 0.0;

    /* the relative rotation in that frame: twist psi about z, bend theta */
    double mqinv[4], q21[4], turn[4], a[4];
    multiply(q2inv, q1, q21);
    conjugate(mq, mqinv);
    multiply(mqinv, q21, turn);
    multiply(turn, mq, a);
    const double mag_out = a[0] * a[0] + a[3] * a[3];
    const double mag_in = a[1] * a[1] + a[2] * a[2];
    const double out = sqrt(mag_out);
    double psi = out != 0.0 ? 2.0 * clipped_acos(a[0] / out) : 0.0;
    if (a[3] < 0.0)
        psi = -psi;
    if (a[3] == 0.0)
        psi = 0.0;
    const double theta = clipped_acos(a[0] * a[0] - a[1] * a[1] - a[2] * a[2] + a[3] * a[3]);
    double cos_phi = 0.0, sin_phi = 0.0; /* (no rotation in the plane: 0, 0) */
    if (mag_in != 0.0 && mag_out == 0.0) {
        const double root = sqrt(mag_in);
        cos_phi = a[2] / root;
        sin_phi = -a[1] / root;
    } else if (mag_in != 0.0) {
        const double root = sqrt(mag_out * mag_in);
        cos_phi = (a[1] * a[3] + a[0] * a[2]) / root;
        sin_phi = (a[2] * a[3] - a[0] * a[1]) / root;
    }

    const double kb_theta = coeff[ROT_K_B] * theta;
    const double tbp[3] = {-kb_theta * sin_phi, kb_theta * cos_phi, 0.0};
    const double ttp[3] = {0.0, 0.0, coeff[ROT_K_T] * psi};
    const double fsp[3] = {-0.5 * ks * len * theta * cos_phi,
                           -0.5 * ks * len * theta * sin_phi, 0.0};
    const double tsp[3] = {0.25 * ks * len * len * theta * sin_phi,
                           -0.25 * ks * len * len * theta * cos_phi, 0.0};
    double turned[3], tb[3], tt[3];
    rotate(mq, fsp, turned);
    for (int c = 0; c < 3; c++)
        fs[c] = fs[c] + turned[c];
    rotate(mq, tsp, turned);
    for (int c = 0; c < 3; c++)
        ts[c] = ts[c] + turned[c];
    rotate(mq, tbp, tb);
    rotate(mq, ttp, tt);

    double lab[3];
    for (int c = 0; c < 3; c++)
        lab[c] = f_rot[c] + fs[c];
    rotate(q2, lab, o->f12);
    for (int c = 0; c < 3; c++)
        lab[c] = ts[c] + tt[c] + tb[c];
    rotate(q2, lab, o->t12);
    for (int c = 0; c < 3; c++)
        lab[c] = ts[c] - tt[c] - tb[c];
    rotate(q2, lab, o->t21);

    const double measure = fr / coeff[ROT_F_RC] + length(fs) / coeff[ROT_F_SC]
                           + length(tb) / coeff[ROT_TAU_BC] + length(tt) / coeff[ROT_TAU_TC];
    o->breaking = measure < 0.0 ? 0.0 : measure; /* (NaN stays NaN, as np.maximum) */

    if (v12) {
        rotational_damping(r, rinv, coeff, v12, w1, w2, o);
        for (int c = 0; c < 3; c++) {
            o->f12[c] = o->f12[c] + o->fd12[c];
            o->t12[c] = o->t12[c] + o->td12[c];
            o->t21[c] = o->t21[c] + o->td21[c];
        }
    }
}

/* -- the kernel --------------------------------------------------------------- */

/* What rotational_bonds reads and writes; the Python side fills it
 * (RotationalBondsView, ase_bpm/laws/compiled.py), field for field. */
struct rotational_bonds {
    int64_t nb;           /* bonds to pass over: of `select`, or all */
    const int64_t *select; /* the law's bonds (NULL: all nb) */
    const int64_t *i_b, *j_b, *type_b; /* first and second atom, type (0: broken) */
    const double *x_nc;   /* positions */
    const double *v_nc;   /* velocities (NULL: undamped) */
    const double *q_nq;   /* orientations, four per atom */
    const double *w_nc;   /* angular velocities (read where damped) */
    const double *box;    /* the cell (bonds.h) */
    double *r0_b;         /* reference lengths; NaN ones taken now, written */
    /* the reference state, REF_WIDTH per bond: the direction along the bond as
     * listed, then +1 where its first atom is LAMMPS's particle 1, -1 where
     * its second is (NaN: unset, taken now: particle 1 the smaller index) */
    const double *dir_bc;
    double *dir_out;      /* the taken states, one row per bond of `select` (or NULL) */
    const double *coeff_t; /* ROT_NCOEFF per bond type */
    int64_t smooth, normalize, breaking, virial;
    double *f_nc, *fd_nc; /* per-atom force and its damping part (NULL: not asked) */
    double *t_nc, *td_nc; /* per-atom torque and its damping part (NULL: not asked) */
    int8_t *broken_b;     /* 1 where a bond breaks now (with `breaking`) */
    double *out;          /* the totals (bonds.h): the virial, with `virial` */
};

/* Adds one bond's force and torques, smoothed by w, to per-atom sums: the
 * force f12 (on particle 2, LAMMPS's force1on2) taken onto the first atom i
 * as listed (w_sense: w, signed by which end i is), its opposite on j, the
 * torques t_i on i and t_j on j; writes the force on i into f_i. */
static inline void add_bond(double *f_nc, double *t_nc, int64_t i, int64_t j,
                            const double *f12, const double *t_i, const double *t_j,
                            double w_sense, double w, double *f_i)
{
    for (int c = 0; c < 3; c++) {
        f_i[c] = f12[c] * w_sense;
        f_nc[3 * i + c] += f_i[c];
        f_nc[3 * j + c] -= f_i[c];
        t_nc[3 * i + c] += t_i[c] * w;
        t_nc[3 * j + c] += t_j[c] * w;
    }
}

/* bond_style bpm/rotational on the bonds of `a` (see struct rotational_bonds).
 *
 * Per bond: the vector r = x[j] - x[i] (minimum image) and, where unset, its
 * reference length (the length now) and direction (r / |r|, also written to
 * dir_out where given); the law; with `breaking`, a bond whose measure B
 * reaches 1 gets broken_b[b] = 1 and gives no force or torque; with
 * `smooth`, forces and torques times 1 - B^4.  Adds the force on i (its
 * opposite on j), the torques on i and j and their damping parts to the
 * per-atom sums and (`virial`) r (x) f to the totals.  A bond of type 0
 * (broken earlier, still listed) is passed over.  The energy of these bonds
 * is zero (as LAMMPS reports it).  Returns the number of bonds that break. */
int64_t rotational_bonds(const struct rotational_bonds *a)
{
    int64_t nbroken = 0;
    struct rotational_out o;
    for (int64_t k = 0; k < a->nb; k++) {
        const int64_t b = a->select ? a->select[k] : k;
        if (a->type_b[b] == 0)
            continue; /* broken earlier, still listed */
        const int64_t i = a->i_b[b], j = a->j_b[b];
        const double *coeff = a->coeff_t + ROT_NCOEFF * a->type_b[b];
        double r_listed[3];
        const double len = bond_vector(a->x_nc, i, j, a->box, r_listed);
        if (isnan(a->r0_b[b]))
            a->r0_b[b] = len;
        double dir[REF_WIDTH];
        const double *given = a->dir_bc + REF_WIDTH * b;
        const double len_inv = 1.0 / len; /* (times the inverse, as LAMMPS takes it) */
        for (int c = 0; c < 3; c++)
            dir[c] = isnan(given[0]) ? r_listed[c] * len_inv : given[c];
        dir[3] = isnan(given[0]) ? (i < j ? 1.0 : -1.0) : given[3];
        if (isnan(given[0]) && a->dir_out)
            for (int c = 0; c < REF_WIDTH; c++)
                a->dir_out[REF_WIDTH * k + c] = dir[c];

        /* LAMMPS's particle 1 first (kept with the bond): r = x_1 - x_2 */
        const int first = dir[3] > 0.0;
        const double sense = first ? -1.0 : 1.0;
        const int64_t p1 = first ? i : j, p2 = first ? j : i;
        double r[3], dir0[3], v12[3];
        for (int c = 0; c < 3; c++) {
            r[c] = r_listed[c] * sense;
            dir0[c] = dir[c] * sense;
        }
        const int damped = a->v_nc != NULL;
        if (damped)
            for (int c = 0; c < 3; c++)
                v12[c] = (a->v_nc[3 * j + c] - a->v_nc[3 * i + c]) * sense;
        rotational_bond(r, a->r0_b[b], dir0, a->q_nq + 4 * p1, a->q_nq + 4 * p2, coeff,
                        (int)a->normalize, damped ? v12 : NULL,
                        damped ? a->w_nc + 3 * p1 : NULL, damped ? a->w_nc + 3 * p2 : NULL,
                        &o);
        if (a->breaking && o.breaking >= 1.0) {
            a->broken_b[b] = 1;
            nbroken++;
            continue; /* as LAMMPS: a bond that breaks gives no force */
        }
        double w = 1.0;
        if (a->smooth) {
            const double b2 = o.breaking * o.breaking;
            w = 1.0 - b2 * b2;
        }
        /* on the first atom as listed: particle 1 gets -force1on2, particle 2 +force1on2 */
        const double w_sense = w * sense;
        double f_i[3], fd_i[3];
        if (damped)
            add_bond(a->fd_nc, a->td_nc, i, j, o.fd12, first ? o.td21 : o.td12,
                     first ? o.td12 : o.td21, w_sense, w, fd_i);
        add_bond(a->f_nc, a->t_nc, i, j, o.f12, first ? o.t21 : o.t12, first ? o.t12 : o.t21,
                 w_sense, w, f_i);
        if (a->virial)
            for (int x = 0; x < 3; x++)
                for (int y = 0; y < 3; y++)
                    a->out[OUT_VIRIAL + 3 * x + y] += r_listed[x] * f_i[y];
    }
    return nbroken;
}
