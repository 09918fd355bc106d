/* Compiled PERI kernels: the peridynamic bond models pmb, lps, ves and eps
 * of BPMPeri (LAMMPS bond_style bpm/peri with the physics of the legacy
 * peri/... pair styles), and pair_style bpm/peri, each a pass that takes the
 * bond vectors from the positions, computes the law and adds the forces to
 * the atoms.
 *
 * The same arithmetic as ase_bpm/laws/peri.py (partial_volume, extension,
 * weighted_volume, dilatation, pmb, lps, ves, eps, past_critical_stretch,
 * PeriContact) and BPMPeri (ase_bpm/models/peri.py: the smallest stretch of
 * each node, the energy left when bonds break), operation for operation;
 * per-atom sums are accumulated in another order than NumPy's, so results
 * agree to round-off.  Forces are true forces: a bond carries V_i V_j
 * following the legacy styles, ((V_i + V_j) / 2)^2 following bond_style
 * bpm/peri (`legacy` in struct peri_bonds; the two agree on equal volumes).
 *
 * The state-based models need each node's dilatation before any bond force:
 * peri_nodes is that first pass (and, at the first evaluation, takes the
 * reference lengths and the weighted and interaction volumes); each law's
 * kernel is the second.  eps adds a pass of its own for the norm of the
 * trial deviatoric force state of each node (the return to the yield
 * surface), in steps only.
 */

#include <stdlib.h>

#include "bonds.h"

/* a bond type's coefficients, in this order (PeriBond.rows); NaN where the
 * type's model has no such coefficient */
enum {
    PERI_C, PERI_K, PERI_G, PERI_LAMBDA, PERI_TAU, PERI_YIELD, PERI_HORIZON, PERI_S00,
    PERI_ALPHA, PERI_MODEL, PERI_NCOEFF
};
/* PERI_MODEL: the model of the type (state-based: all but pmb) */
enum { MODEL_PMB, MODEL_LPS, MODEL_VES, MODEL_EPS };

#define NEAR_ZERO 2.2204e-16 /* extensions below this count as zero (legacy PERI) */

/* What every PERI kernel reads and writes (ase_bpm/laws/compiled.py,
 * PeriBonds, mirrors it field for field: all 8 bytes wide). */
struct peri_bonds {
    int64_t nb;             /* bonds visited */
    const int64_t *select;  /* their indices in the set (NULL: 0 .. nb - 1) */
    const int64_t *i_b, *j_b, *type_b;
    double *r0_b;           /* reference lengths (peri_nodes takes the NaN ones now) */
    const double *coeff_t;  /* PERI_NCOEFF per bond type */
    int64_t natoms;
    const double *x_nc, *box, *vol_n;
    const double *m_n;      /* weighted volumes */
    const double *theta_n;  /* dilatation (state-based bonds; NULL: none) */
    const double *smin_n;   /* each node's smallest stretch in the step before (NULL: none) */
    const double *lambda_n; /* eps: plastic multiplier as of the step before */
    const double *history_b; /* ves, eps: per-bond history of the set's bonds (NaN: none) */
    double spacing;         /* lattice spacing (partial volumes) */
    double dt;              /* timestep (ves) */
    int64_t breaking;       /* test Parks' criterion (needs smin_n) */
    int64_t acts;           /* a bond that breaks still gives its force (legacy steps) */
    int64_t advance;        /* a step: history advances */
    int64_t virial;         /* add the virial to out */
    int64_t legacy;         /* 0: bond_style bpm/peri; 1: the legacy peri/... styles; 2:
                             * legacy, eps as BPMPeri had it before its follows option
                             * (laws/peri.py, RECORDED) */
    double *f_nc;
    int8_t *broken_b;       /* 1 where a bond breaks (one per bond of the set) */
    double *smin_new_n;     /* this step's smallest stretch of each node (NULL: not kept) */
    double *history_out;    /* ves, eps: the updated history, one row per visited bond */
    double *lambda_out;     /* eps: the updated plastic multiplier */
    double *out;            /* NOUT sums */
};

/* one bond, gathered */
struct peri_bond {
    int64_t b, i, j;
    const double *c;        /* its type's coefficients */
    double r[3], len, rinv, r0, dr, stretch, scale, vv;
};

/* Share of the partner's volume the bond sees (partial_volume). */
static inline double partial_volume(double r0, double horizon, double spacing)
{
    const double half = 0.5 * spacing;
    if (fabs(r0 - horizon) <= half)
        return (horizon + half - r0) / spacing;
    return 1.0;
}

/* fmax, inlined: the larger of a and b, or the one that is not NaN (no
 * branch on the comparison: it goes either way, bond after bond) */
static inline double larger(double a, double b)
{
    const double m = a > b ? a : b;
    return isnan(b) ? a : m;
}

/* x with NaN as 0 and infinities as the largest finite values (np.nan_to_num). */
static inline double nan_to_num(double x)
{
    if (isnan(x))
        return 0.0;
    if (isinf(x))
        return x > 0 ? 1.7976931348623157e308 : -1.7976931348623157e308;
    return x;
}

static inline int64_t bond_index(const struct peri_bonds *s, int64_t k)
{
    return s->select ? s->select[k] : k;
}

/* The volume factor of a bond or contact between nodes of volumes vi and
 * vj (laws/peri.py, volume_product): V_i V_j (legacy), or the square of
 * their mean (bond_style bpm/peri). */
static inline double volume_product(double vi, double vj, int64_t legacy)
{
    const double mean = 0.5 * (vi + vj);
    return legacy ? vi * vj : mean * mean;
}

/* Bond b of the set: its vector, length, extension, stretch, partial volume
 * and volume factor (the reference length must be known). */
static inline void gather(const struct peri_bonds *s, int64_t b, struct peri_bond *p)
{
    p->b = b;
    p->i = s->i_b[b];
    p->j = s->j_b[b];
    p->c = s->coeff_t + PERI_NCOEFF * s->type_b[b];
    p->len = bond_vector(s->x_nc, p->i, p->j, s->box, p->r);
    p->rinv = p->len > 0.0 ? 1.0 / p->len : 0.0;
    p->r0 = s->r0_b[b];
    double dr = p->len - p->r0;
    if (fabs(dr) < NEAR_ZERO)
        dr = 0.0;
    p->dr = dr;
    p->stretch = dr / p->r0;
    p->scale = partial_volume(p->r0, p->c[PERI_HORIZON], s->spacing);
    p->vv = volume_product(s->vol_n[p->i], s->vol_n[p->j], s->legacy);
}

/* The smallest value at a node (NaN: none yet; always written, without a
 * branch on the comparison). */
static inline void keep_smaller(double *at, double value)
{
    const double now = *at;
    *at = value >= now ? now : value;
}

/* Parks' criterion: the stretch beyond s00 - alpha s_min, s_min the larger
 * of the two nodes' smallest stretches in the step before (NaN at both: no
 * history, no break); notes the stretch for the next step's test (following
 * bond_style bpm/peri only where the bond stays, legacy always).  Marks the
 * bond and returns 1 if it breaks. */
static inline int parks(const struct peri_bonds *s, const struct peri_bond *p, int64_t *nbroken)
{
    int breaks = 0;
    if (s->breaking && s->smin_n) {
        const double smin = larger(s->smin_n[p->i], s->smin_n[p->j]);
        const double critical = p->c[PERI_S00] - p->c[PERI_ALPHA] * smin;
        breaks = p->stretch > critical;
    }
    if (s->smin_new_n && (s->legacy || !breaks)) {
        keep_smaller(s->smin_new_n + p->i, p->stretch);
        keep_smaller(s->smin_new_n + p->j, p->stretch);
    }
    if (!breaks)
        return 0;
    s->broken_b[p->b] = 1;
    ++*nbroken;
    return 1;
}

/* A virial summed over bonds: r (x) r s is symmetric, so six components
 * (kept in registers through a kernel's loop; added to out at its end). */
struct virial {
    double xx, yy, zz, xy, xz, yz;
};

static inline void add_symmetric(struct virial *w, const double *r, double s)
{
    const double x = r[0] * s, y = r[1] * s, z = r[2] * s;
    w->xx += r[0] * x;
    w->yy += r[1] * y;
    w->zz += r[2] * z;
    w->xy += r[0] * y;
    w->xz += r[0] * z;
    w->yz += r[1] * z;
}

static void add_to_out(double *out, const struct virial *w)
{
    const double full[9] = {w->xx, w->xy, w->xz, w->xy, w->yy, w->yz, w->xz, w->yz, w->zz};
    for (int k = 0; k < 9; k++)
        out[OUT_VIRIAL + k] += full[k];
}

/* The bond's forces: fi on i towards j, fj on j towards i, along the bond;
 * the virial of their mean (that of BondSet.sum_forces, to round-off). */
static inline void add_forces(const struct peri_bonds *s, const struct peri_bond *p, double fi,
                              double fj, struct virial *w)
{
    if (fi == fj) {
        const double f = fi * p->rinv;
        add_pair(s->f_nc, p->i, p->j, p->r, f);
        if (s->virial)
            add_symmetric(w, p->r, f);
        return;
    }
    for (int c = 0; c < 3; c++) {
        s->f_nc[3 * p->i + c] += p->r[c] * (fi * p->rinv);
        s->f_nc[3 * p->j + c] -= p->r[c] * (fj * p->rinv);
    }
    if (s->virial)
        add_symmetric(w, p->r, 0.5 * (fi + fj) * p->rinv);
}

/* 1/m per node (0 without bonds), and zeroed node sums: `extra` arrays of
 * natoms doubles after it; NULL when out of memory. */
static double *node_scratch(const struct peri_bonds *s, int extra)
{
    const int64_t n = s->natoms;
    double *minv = calloc((size_t)(n * (1 + extra)) + 1, sizeof(double));
    if (!minv)
        return NULL;
    for (int64_t k = 0; k < n; k++)
        minv[k] = s->m_n[k] > 0.0 ? 1.0 / s->m_n[k] : 0.0;
    return minv;
}

/* 0.5 sum_i V_i k_i theta_i^2, k_i the mean of ksum_n over count_n bonds
 * (the volumetric energy of lps, ves and eps). */
static double volumetric(const struct peri_bonds *s, const double *theta_n,
                         const double *ksum_n, const double *count_n)
{
    double energy = 0.0;
    for (int64_t k = 0; k < s->natoms; k++) {
        const double kmean = count_n[k] > 0.0 ? ksum_n[k] / count_n[k] : 0.0;
        energy += s->vol_n[k] * kmean * theta_n[k] * theta_n[k];
    }
    return 0.5 * energy;
}

static inline void add_node_pair(double *to_n, int64_t i, int64_t j, double to_i, double to_j)
{
    to_n[i] += to_i;
    to_n[j] += to_j;
}

/* The node pass over all nb bonds of the set: takes the reference lengths
 * not known yet (the length now), and sums per node what is not NULL:
 * m_sum_n the weighted volume (weighted_volume), theta_n the dilatation of
 * the state-based bonds (dilatation, with s->m_n; zero without bonds).
 * Returns 0, or -1 when out of memory. */
int64_t peri_nodes(const struct peri_bonds *s, double *m_sum_n, double *theta_n)
{
    double *sum_n = NULL;
    if (theta_n) {
        sum_n = calloc((size_t)s->natoms + 1, sizeof(double));
        if (!sum_n)
            return -1;
    }
    for (int64_t k = 0; k < s->nb; k++) {
        const int64_t b = bond_index(s, k), i = s->i_b[b], j = s->j_b[b];
        if (isnan(s->r0_b[b])) {
            double r[3];
            s->r0_b[b] = bond_vector(s->x_nc, i, j, s->box, r);
        }
        if (!m_sum_n && !sum_n)
            continue;
        const double *c = s->coeff_t + PERI_NCOEFF * s->type_b[b];
        if (m_sum_n) {
            const double w = s->r0_b[b] * partial_volume(s->r0_b[b], c[PERI_HORIZON],
                                                         s->spacing);
            add_node_pair(m_sum_n, i, j, w * s->vol_n[j], w * s->vol_n[i]);
        }
        if (sum_n && c[PERI_MODEL] != MODEL_PMB) {
            struct peri_bond p;
            gather(s, b, &p);
            const double w = p.dr * p.scale;
            add_node_pair(sum_n, i, j, w * s->vol_n[j], w * s->vol_n[i]);
        }
    }
    if (sum_n) {
        for (int64_t k = 0; k < s->natoms; k++)
            theta_n[k] = s->m_n[k] > 0.0 ? 3.0 * sum_n[k] / s->m_n[k] : 0.0;
        free(sum_n);
    }
    return 0;
}

/* pmb on the bonds visited: c s scale V_i V_j, energy f dr / 2 each (that of
 * the bonds that break is released).  Returns how many break. */
int64_t peri_pmb(const struct peri_bonds *s)
{
    int64_t nbroken = 0;
    double kept = 0.0, released = 0.0;
    struct virial w = {0};
    for (int64_t k = 0; k < s->nb; k++) {
        struct peri_bond p;
        gather(s, bond_index(s, k), &p);
        const double f = p.c[PERI_C] * p.scale * p.vv * (p.dr / p.r0);
        const double energy = 0.5 * f * p.dr;
        if (parks(s, &p, &nbroken)) {
            released += energy;
            if (!s->acts)
                continue;
        } else {
            kept += energy;
        }
        add_forces(s, &p, f, f, &w);
    }
    s->out[OUT_ENERGY] += kept;
    s->out[OUT_RELEASED] += released;
    add_to_out(s->out, &w);
    return nbroken;
}

/* What lps, ves and eps share: per node 1/m and, over the law's bonds, the
 * count and the sum of K (each node's mean bulk modulus, for the volumetric
 * energy), and `extra` more node sums of the law's own; the energy, virial
 * and breaks so far.  Their energy goes whole to out[OUT_ENERGY]: what the
 * bonds that break take with them is the model's to work out
 * (peri_kept_energy). */
struct state_law {
    const double *theta;  /* the dilatation (s->theta_n) */
    double *minv, *ksum, *count, *extra;
    double energy;
    struct virial w;
    int64_t nbroken;
    int64_t k;  /* the bond visited now (state_law_next) */
};

/* Returns 0, or -1 when out of memory. */
static int state_law_begin(const struct peri_bonds *s, struct state_law *t, int extra)
{
    const int64_t n = s->natoms;
    t->theta = s->theta_n;
    t->minv = node_scratch(s, 2 + extra);
    if (!t->minv)
        return -1;
    t->ksum = t->minv + n;
    t->count = t->ksum + n;
    t->extra = t->count + n;
    t->energy = 0.0;
    t->w = (struct virial){0};
    t->nbroken = 0;
    t->k = -1;
    return 0;
}

/* The next bond visited, into p: 0 when there is none. */
static inline int state_law_next(const struct peri_bonds *s, struct state_law *t,
                                 struct peri_bond *p)
{
    if (++t->k >= s->nb)
        return 0;
    gather(s, bond_index(s, t->k), p);
    return 1;
}

/* Bond p's end: its node sums, Parks' test, its forces fi on i and fj on j. */
static inline void state_law_bond(const struct peri_bonds *s, struct state_law *t,
                                  const struct peri_bond *p, double fi, double fj)
{
    add_node_pair(t->ksum, p->i, p->j, p->c[PERI_K], p->c[PERI_K]);
    add_node_pair(t->count, p->i, p->j, 1.0, 1.0);
    if (parks(s, p, &t->nbroken) && !s->acts)
        return;
    add_forces(s, p, fi, fj, &t->w);
}

/* The energy (with the volumetric part) and virial to out; returns the breaks. */
static int64_t state_law_end(const struct peri_bonds *s, struct state_law *t)
{
    s->out[OUT_ENERGY] += t->energy + volumetric(s, s->theta_n, t->ksum, t->count);
    add_to_out(s->out, &t->w);
    free(t->minv);
    return t->nbroken;
}

/* lps on the bonds visited (symmetric in i and j).  Returns how many break,
 * or -1 when out of memory. */
int64_t peri_lps(const struct peri_bonds *s)
{
    struct state_law t;
    struct peri_bond p;
    if (state_law_begin(s, &t, 0))
        return -1;
    while (state_law_next(s, &t, &p)) {
        const int64_t i = p.i, j = p.j;
        const double *theta = t.theta, *minv = t.minv;
        const double K = p.c[PERI_K], G = p.c[PERI_G], dr = p.dr, r0 = p.r0;
        const double wt_i = theta[i] * minv[i], wt_j = theta[j] * minv[j];
        const double w_sum = minv[i] + minv[j];
        const double a = p.scale * p.vv;
        const double f = a * ((3.0 * K - 5.0 * G) * (wt_i + wt_j)
                              + 15.0 * G * w_sum * dr / r0);
        const double dev_i = dr - theta[i] * r0 / 3.0, dev_j = dr - theta[j] * r0 / 3.0;
        t.energy += 7.5 * G / r0 * a * (dev_i * dev_i * minv[i] + dev_j * dev_j * minv[j]);
        state_law_bond(s, &t, &p, f, f);
    }
    return state_law_end(s, &t);
}

/* One step of dt of a ves back extension relaxing with time constant tau:
 * decay = exp(-dt / tau), written exp(-1 / c1) with c1 = tau / dt, and
 * beta = 1 - c1 (1 - decay).  Kept for the tau it was worked out for: a
 * bond of another tau works it out anew (an exp per bond type in a run of
 * bonds, not two per bond). */
struct relaxation {
    double tau, decay, beta;
};

static inline void relaxation_for(struct relaxation *step, double tau, double dt)
{
    if (tau == step->tau)
        return;
    const double c1 = tau / dt;
    step->tau = tau;
    step->decay = exp(-1.0 / c1);
    step->beta = 1.0 - c1 * (1.0 - step->decay);
}

/* ves on the bonds visited: legacy, each end with its own dilatation and
 * history (ed_i, edb_i, ed_j, edb_j); bond_style bpm/peri, one deviatoric
 * extension per bond with the mean dilatation of its nodes and one history
 * (the first pair, written to both).  The back extensions take one step of
 * dt when advancing.  Returns how many break, or -1 when out of memory. */
int64_t peri_ves(const struct peri_bonds *s)
{
    struct state_law t;
    struct peri_bond p;
    if (state_law_begin(s, &t, 0))
        return -1;
    struct relaxation step = {NAN, 0.0, 0.0};
    while (state_law_next(s, &t, &p)) {
        const double *theta = t.theta, *minv = t.minv;
        const int64_t i = p.i, j = p.j, ends[2] = {p.i, p.j};
        const double K = p.c[PERI_K], G = p.c[PERI_G], lam = p.c[PERI_LAMBDA];
        const double dr = p.dr, r0 = p.r0;
        if (s->advance)
            relaxation_for(&step, p.c[PERI_TAU], s->dt);
        const double a = p.scale * p.vv;
        const double elastic = 3.0 * K * a * (theta[i] * minv[i] + theta[j] * minv[j]);
        const double gfac = 15.0 * G * a * (minv[i] + minv[j]) / r0;
        const double mean_theta = 0.5 * (theta[i] + theta[j]);
        const double *old = s->history_b + 4 * p.b;
        double *new = s->history_out + 4 * t.k;
        double f[2];
        for (int end = 0; end < 2; end++) {
            const int64_t node = ends[end];
            const int slot = s->legacy ? end : 0;
            const double ed = dr - (s->legacy ? theta[node] : mean_theta) * r0 / 3.0;
            const double ed_old = nan_to_num(old[2 * slot]);
            const double edb_old = nan_to_num(old[2 * slot + 1]);
            double edb = edb_old;
            if (s->advance)
                edb = ed_old * (1.0 - step.decay) + edb_old * step.decay
                      + step.beta * (ed - ed_old);
            new[2 * end] = ed;
            new[2 * end + 1] = edb;
            f[end] = elastic + gfac * ((1.0 - lam) * ed + lam * (ed - edb));
            t.energy += 7.5 * G / r0 * a * minv[node]
                        * ((1.0 - lam) * ed * ed + lam * ((ed - edb) * (ed - edb)));
        }
        state_law_bond(s, &t, &p, f[0], f[1]);
    }
    return state_law_end(s, &t);
}

/* eps: the deviatoric extension of one end, ed = dr - theta r0 / 3 (legacy,
 * either form), or of the bond, with the mean dilatation of its nodes
 * (bond_style bpm/peri) */
static inline double deviatoric(const struct peri_bond *p, const double *theta, int64_t node,
                                int64_t legacy)
{
    const double th = legacy ? theta[node] : 0.5 * (theta[p->i] + theta[p->j]);
    return p->dr - th * p->r0 / 3.0;
}

/* eps on the bonds visited (laws/peri.py, eps): a first pass sums each
 * node's shear modulus, yield value and squared norm of the deviatoric
 * force state (bond_style bpm/peri: the node's own state on each bond,
 * 15 G (ed - edp) / (m_i r0), whose norm Mitchell's yield test takes, not
 * the bond's, the sum of its two nodes' states; legacy: the bond's trial
 * state at each end, with the reference build's dilatation factor); a
 * node past the yield surface gets its plastic multiplier increment; the
 * second pass returns each bond's deviatoric force (legacy: per end, by its
 * node, the plastic extension updated as the reference build does, or
 * forgotten below yield; bond_style bpm/peri: per bond, by the mean norm of
 * its nodes, the exact radial return; before the option: per end, by its
 * node's norm of the trial state itself, the exact radial return).  In a step only: else the stored
 * plastic extensions are used as they are.  Returns how many break, or -1
 * when out of memory. */
int64_t peri_eps(const struct peri_bonds *s)
{
    const int64_t n = s->natoms;
    struct state_law t;
    if (state_law_begin(s, &t, 5))
        return -1;
    double *gsum = t.extra, *gcount = gsum + n, *norm = gcount + n, *ymax = norm + n;
    double *dlambda = ymax + n;
    const double *theta = s->theta_n, *minv = t.minv;
    const int64_t legacy = s->legacy, before = s->legacy == 2;
    for (int64_t k = 0; s->advance && k < s->nb; k++) {  /* the node sums */
        struct peri_bond p;
        gather(s, bond_index(s, k), &p);
        const int64_t i = p.i, j = p.j;
        const double *c = p.c;
        add_node_pair(gsum, i, j, c[PERI_G], c[PERI_G]);
        add_node_pair(gcount, i, j, 1.0, 1.0);
        if (c[PERI_YIELD] > ymax[i])
            ymax[i] = c[PERI_YIELD];
        if (c[PERI_YIELD] > ymax[j])
            ymax[j] = c[PERI_YIELD];
        const double *h = s->history_b + 2 * p.b;
        if (!legacy) {  /* each node's own state on the bond, shear / m (Mitchell's):
                         * 1/m comes out of the node's sum */
            const double shear = 15.0 * c[PERI_G] * (deviatoric(&p, theta, i, 0)
                                                     - nan_to_num(h[0])) / p.r0;
            const double weight = shear * shear * p.scale;
            add_node_pair(norm, i, j, weight * s->vol_n[j], weight * s->vol_n[i]);
            continue;
        }
        /* the bond's trial state at each end (the reference build: with its factor) */
        const double nfac = before
                                ? 15.0 * c[PERI_G] * (minv[i] + minv[j]) / p.r0
                                : 15.0 * c[PERI_G] * (theta[i] * minv[i] + theta[j] * minv[j])
                                      / p.r0;
        const double t_i = nfac * (deviatoric(&p, theta, i, 1) - nan_to_num(h[0]));
        const double t_j = nfac * (deviatoric(&p, theta, j, 1) - nan_to_num(h[1]));
        add_node_pair(norm, i, j, t_i * t_i * p.scale * s->vol_n[j],
                      t_j * t_j * p.scale * s->vol_n[i]);
    }
    for (int64_t k = 0; k < n; k++) {  /* the norms and the multiplier increments */
        norm[k] = legacy ? sqrt(norm[k]) : minv[k] * sqrt(norm[k]);
        s->lambda_out[k] = s->lambda_n[k];
        const double limit = sqrt(2.0 * ymax[k]);
        const int yields = before ? norm[k] > limit : 0.5 * norm[k] * norm[k] - ymax[k] > 0.0;
        if (!(s->advance && yields && ymax[k] > 0.0))
            continue;
        const double g = gcount[k] > 0.0 ? gsum[k] / gcount[k] : 0.0;
        dlambda[k] = (norm[k] / (limit > 0.0 ? limit : 1.0) - 1.0) * s->m_n[k]
                     / (g > 0.0 ? 15.0 * g : 1.0);
        s->lambda_out[k] += dlambda[k];
    }
    struct peri_bond p;
    while (state_law_next(s, &t, &p)) {
        const int64_t i = p.i, j = p.j, ends[2] = {p.i, p.j};
        const double K = p.c[PERI_K], G = p.c[PERI_G], r0 = p.r0;
        const double a = p.scale * p.vv;
        const double elastic = 3.0 * K * a * (theta[i] * minv[i] + theta[j] * minv[j]);
        const double gfac = 15.0 * G * (minv[i] + minv[j]) / r0;
        const double *old = s->history_b + 2 * p.b;
        double *new = s->history_out + 2 * t.k;
        double f[2];
        if (!legacy) {  /* the bond returns radially by its nodes' mean norm */
            const double ed = deviatoric(&p, theta, i, 0), h = nan_to_num(old[0]);
            const double limit = sqrt(2.0 * p.c[PERI_YIELD]);
            const double norm_b = 0.5 * (norm[i] + norm[j]);
            const double radial = s->advance && norm_b > limit ? limit / norm_b : 1.0;
            const double trial = gfac * (ed - h) * radial;
            const double h_new = h + (ed - h) * (1.0 - radial);
            new[0] = new[1] = s->advance ? h_new : h;
            f[0] = f[1] = elastic + a * trial;
            t.energy += 7.5 * G / r0 * a * (minv[i] + minv[j]) * (ed - h_new) * (ed - h_new);
        } else if (before) {  /* each end by its node, radially */
            for (int end = 0; end < 2; end++) {
                const int64_t node = ends[end];
                const double ed = deviatoric(&p, theta, node, 1), h = nan_to_num(old[end]);
                const double limit = sqrt(2.0 * ymax[node]);
                const double radial = dlambda[node] > 0.0 ? limit / norm[node] : 1.0;
                double trial = gfac * (ed - h);
                new[end] = h;
                if (s->advance) {
                    new[end] = h + (ed - h) * (1.0 - radial);
                    trial = trial * radial;
                }
                f[end] = elastic + a * trial;
                const double elastic_ext = ed - new[end];
                t.energy += 7.5 * G / r0 * a * minv[node] * elastic_ext * elastic_ext;
            }
        } else {  /* each end by its node, as the reference build */
            for (int end = 0; end < 2; end++) {
                const int64_t node = ends[end];
                const double ed = deviatoric(&p, theta, node, 1), h = nan_to_num(old[end]);
                double back = gfac * (ed - h), h_new = s->advance ? 0.0 : h;
                if (dlambda[node] > 0.0) {
                    back = sqrt(2.0 * ymax[node]) * back / norm[node];
                    h_new = h + back * dlambda[node];
                }
                new[end] = s->advance ? h_new : h;
                f[end] = elastic + a * back;
                t.energy += 7.5 * G / r0 * a * minv[node] * (ed - h) * (ed - h);
            }
        }
        state_law_bond(s, &t, &p, f[0], f[1]);
    }
    return state_law_end(s, &t);
}

/* The elastic energy once the bonds marked in s->broken_b are gone
 * (BPMPeri._split_energy): pmb bonds keep their own; the state-based ones
 * take the lps energy with the dilatation of the bonds that stay.  Visits
 * all nb bonds of the set; s->theta_n is not read.  Returns the energy, NaN
 * when out of memory. */
double peri_kept_energy(const struct peri_bonds *s)
{
    const int64_t n = s->natoms;
    double *minv = node_scratch(s, 4);
    if (!minv)
        return NAN;
    double *ksum = minv + n, *count = ksum + n, *sum = count + n, *theta = sum + n;
    int any_state = 0;
    for (int64_t b = 0; b < s->nb; b++) {
        const double *c = s->coeff_t + PERI_NCOEFF * s->type_b[b];
        if (s->broken_b[b] || c[PERI_MODEL] == MODEL_PMB)
            continue;
        struct peri_bond p;
        gather(s, b, &p);
        const double w = p.dr * p.scale;
        add_node_pair(sum, p.i, p.j, w * s->vol_n[p.j], w * s->vol_n[p.i]);
        add_node_pair(ksum, p.i, p.j, c[PERI_K], c[PERI_K]);
        add_node_pair(count, p.i, p.j, 1.0, 1.0);
        any_state = 1;
    }
    for (int64_t k = 0; k < n; k++)
        theta[k] = s->m_n[k] > 0.0 ? 3.0 * sum[k] / s->m_n[k] : 0.0;
    double pmb = 0.0, state = 0.0;
    for (int64_t b = 0; b < s->nb; b++) {
        if (s->broken_b[b])
            continue;
        struct peri_bond p;
        gather(s, b, &p);
        if (p.c[PERI_MODEL] == MODEL_PMB) {
            pmb += 0.5 * (p.c[PERI_C] * p.scale * p.vv * (p.dr / p.r0)) * p.dr;
            continue;
        }
        const double G = p.c[PERI_G], a = p.scale * p.vv;
        const double dev_i = p.dr - theta[p.i] * p.r0 / 3.0;
        const double dev_j = p.dr - theta[p.j] * p.r0 / 3.0;
        state += 7.5 * G / p.r0 * a * (dev_i * dev_i * minv[p.i] + dev_j * dev_j * minv[p.j]);
    }
    if (any_state)
        state += volumetric(s, theta, ksum, count);
    free(minv);
    return pmb + state;
}

/* pair_style bpm/peri on the listed pairs `select` (NULL: all np) of a
 * neighbour list, r = x[j] - x[i] + shift (shift_pc NULL: no shifts, an
 * open box): pairs closer than their contact
 * distance d (reach_p[s] for the s-th pair visited, or `reach` where reach_p
 * is NULL) repel with 15 k v (r - d) / horizon, energy f (r - d) / 2, v the
 * volume factor (volume_product; `legacy` as in struct peri_bonds).
 * coeff_tt: k, horizon per type pair (ntypes x ntypes).  Adds to f_nc and
 * out (energy, virial with want_virial).  Returns how many touch. */
int64_t peri_contacts(int64_t np, const int64_t *select, const int64_t *i_p,
                      const int64_t *j_p, const double *shift_pc, const int64_t *types_n,
                      int64_t ntypes, const double *x_nc, const double *vol_n,
                      const double *coeff_tt, double reach, const double *reach_p,
                      int64_t legacy, int64_t want_virial, double *f_nc, double *out)
{
    int64_t ntouch = 0;
    double energy = 0.0;
    struct virial w = {0};
    for (int64_t s = 0; s < np; s++) {
        const int64_t p = select ? select[s] : s;
        const int64_t i = i_p[p], j = j_p[p];
        const double *shift = image_shift(shift_pc, p);
        double r[3];
        for (int k = 0; k < 3; k++)
            r[k] = x_nc[3 * j + k] - x_nc[3 * i + k] + shift[k];
        const double d = reach_p ? reach_p[s] : reach, rsq = dot(r, r);
        if (!(rsq < d * d))
            continue;
        ntouch++;
        const double *c = coeff_tt + 2 * (types_n[i] * ntypes + types_n[j]);
        const double len = sqrt(rsq), rinv = len > 0.0 ? 1.0 / len : 0.0;
        const double gap = len - d;
        const double f = 15.0 * c[0] * volume_product(vol_n[i], vol_n[j], legacy) * gap / c[1];
        energy += 0.5 * f * gap;
        add_pair(f_nc, i, j, r, f * rinv);
        if (want_virial)
            add_symmetric(&w, r, f * rinv);
    }
    out[OUT_ENERGY] += energy;
    add_to_out(out, &w);
    return ntouch;
}
