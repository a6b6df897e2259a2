/* The street's background shader: ground, facades and sky along one render-space line (rollcam.sim.render.shader).
 *
 * The one copy of the background's materials: every render path (the fast path, the brute-force reference,
 * the static layer) shades through rollcam_background_line, and the walkers' sun test is rollcam_sun_blocked.
 *
 * Written for gcc to vectorise (8 pixels a step with AVX-512, 4 with AVX2; x86-64 builds carry both clones and
 * a plain one, picked at load by the CPU): a line's pixels are first classified by what their rays hit (sky,
 * asphalt, sidewalk, one facade), and each run of one class is shaded by that material's loop alone. The pixel
 * loops have no branches (conditions select values), no calls, `restrict` pointers, and only the forms gcc 12's
 * vectoriser accepts (the comments at each say which). It is compiled without -ffast-math and with
 * -ffp-contract=off, so every clone performs the same IEEE operations in the same order: the image does not
 * depend on which one runs.
 *
 * Tables: rollcam/sim/render/world.py's layouts (rollcam_shade_layout reports the columns read here, and the loader
 * checks them), with the building lookup and table as rollcam.sim.render.tables pads them: `lut` holds n_bins + 1
 * entries per side, the last one and every empty bin naming row n_bld of `bld`, a sentinel building of height
 * -1e300 that no ray hits and no shadow comes from (so no table read depends on a condition).
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

/* ---- table columns (rollcam/sim/render/world.py) ---- */
enum { C_FX = 0, C_FY = 1, C_CX = 2, C_CY = 3, C_TRANSPOSED = 6 };
enum { L_SUN = 0, L_SUN_RGB = 3, L_AMB = 6, L_HORIZON = 9, L_ZENITH = 12, L_HAZE = 15, L_FOG = 18, L_GLOW = 19 };
enum { W_KIND = 0, W_ROAD = 1, W_CURB = 2, W_FACADE = 4, W_YHALF = 5, W_ASPHALT = 6, W_SIDEWALK = 9,
       W_CROSS = 12, W_SEED = 13, W_LEVEL = 14, W_BIN = 15 };
enum { KIND_STREET = 0, KIND_FLAT = 2 };
enum { B_Y0 = 1, B_HEIGHT = 3, B_RGB = 4, B_WIN_RGB = 7, B_FLOOR = 10, B_WIN_W = 11, B_WIN_SP = 12, B_LIT = 13,
       B_MAT = 14, BLD_COLS = 15 };
enum { MAT_PLASTER = 0, MAT_BRICK = 1, MAT_STONE = 2, MAT_GLASS = 3 };

/* A condition in the pixel loop: as wide as a double, so that its vector masks match the double lanes (gcc
 * does not vectorise selects mixing 32- and 64-bit masks). */
typedef int64_t flag;

#define FOG_STEPS 16
#define FOG_N (64 * FOG_STEPS + 1)
/* Largest hit coordinate (metres) shaded: beyond it the fog leaves only haze (the transmittance is 0 from 64 fog
 * distances on), whatever the material, and below it every lattice and cell index (at most 9 per metre) fits
 * an int32. */
#define COORD_MAX 1.0e8

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(ROLLCAM_NO_CLONES)
#define CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define CLONES
#endif

static double fog_table[FOG_N];
/* FOG_N - 1 steps in x, set at load: a value the compiler cannot fold (folding it into fog_transmittance's clamp
 * had gcc split the loop into branches it then would not vectorise). */
static double fog_x_max;

__attribute__((constructor)) static void fill_fog_table(void) {
    for (int k = 0; k < FOG_N - 1; k++)
        fog_table[k] = exp(-(double)k / FOG_STEPS);
    fog_table[FOG_N - 1] = 0.0; /* x >= 64: transmittance 0 (below 2e-28) */
    fog_x_max = (double)(FOG_N - 1) / FOG_STEPS;
}

/* v limited to +-COORD_MAX (NaN to -COORD_MAX), so that its conversion to a 32-bit integer is defined. */
static inline __attribute__((always_inline)) double clampc(double v) {
    return v > -COORD_MAX ? (v < COORD_MAX ? v : COORD_MAX) : -COORD_MAX;
}

/* Integer lattice hash to [0, 1) (32-bit wrap-around arithmetic). */
static inline __attribute__((always_inline)) double hash01(int32_t ix, int32_t iy, uint32_t seed) {
    uint32_t h = (uint32_t)ix * 374761393u + (uint32_t)iy * 668265263u + seed * 2147483647u;
    h = (h ^ (h >> 13)) * 1274126177u;
    h = h ^ (h >> 16);
    return (double)(int32_t)(h & 0xFFFFFFu) * (1.0 / 16777216.0);
}

/* Smooth value noise in [0, 1) on the unit lattice. */
static inline __attribute__((always_inline)) double value_noise(double x, double y, uint32_t seed) {
    double fx0 = floor(x), fy0 = floor(y);
    double fx = x - fx0, fy = y - fy0;
    int32_t ix = (int32_t)fx0, iy = (int32_t)fy0;
    double a = hash01(ix, iy, seed), b = hash01(ix + 1, iy, seed);
    double c = hash01(ix, iy + 1, seed), d = hash01(ix + 1, iy + 1, seed);
    double sx = fx * fx * (3.0 - 2.0 * fx), sy = fy * fy * (3.0 - 2.0 * fy);
    return (a + (b - a) * sx) * (1.0 - sy) + (c + (d - c) * sx) * sy;
}

/* exp(-x) for x >= 0 to a relative 1e-10: the table's step (`table`: fog_table) and a degree-5 Taylor series
 * of the rest; 0 from x = 64 (`x_max`: fog_x_max) on. */
static inline __attribute__((always_inline)) double fog_transmittance(double x, const double *restrict table,
                                                                      double x_max) {
    double xc = x < x_max ? x : x_max;
    int32_t k = (int32_t)(xc * FOG_STEPS);
    double r = xc - k * (1.0 / FOG_STEPS);
    double p = 1.0 - r * (1.0 - r * (0.5 - r * (1.0 / 6.0 - r * (1.0 / 24.0 - r * (1.0 / 120.0)))));
    return table[k] * p;
}

/* Bin of the building lookup holding street coordinate y (the street repeats every 2 y_half), or n_bins (the
 * lookup's sentinel entry) outside it. */
static inline __attribute__((always_inline)) int32_t street_bin(double y, double y_half, double inv_period,
                                                                double inv_bin, int32_t n_bins) {
    double yy = clampc(y) + y_half;
    yy -= floor(yy * inv_period) * (2.0 * y_half);
    int32_t i = (int32_t)(yy * inv_bin);
    return ((i >= 0) & (i < n_bins)) ? i : n_bins;
}

/* The sky in direction d (unnormalised): its horizon-to-zenith blend s and the sun's glow (weights of the
 * horizon, zenith and sun colours). */
static inline __attribute__((always_inline)) void sky_weights(double dx, double dy, double dz,
                                                              const double *restrict light, double *s_out,
                                                              double *glow_out) {
    double n = sqrt(dx * dx + dy * dy + dz * dz);
    double e = dz / n;
    double s = sqrt(e > 0.0 ? e : 0.0);
    double cosg = (dx * light[L_SUN] + dy * light[L_SUN + 1] + dz * light[L_SUN + 2]) / n;
    double c2 = cosg * cosg, c4 = c2 * c2, c8 = c4 * c4, c16 = c8 * c8;
    *s_out = s;
    *glow_out = cosg > 0.0 ? c16 * c16 * 0.6 : 0.0;
}

/* Building row on `side` (0 west, 1 east) at street coordinate y (the sentinel row where none stands). */
static inline __attribute__((always_inline)) int64_t building_at(const int64_t *restrict lut, int32_t n_bins,
                                                                int side, double y, const double *restrict world) {
    double y_half = world[W_YHALF];
    return lut[side * (n_bins + 1) + street_bin(y, y_half, 1.0 / (2.0 * y_half), 1.0 / world[W_BIN], n_bins)];
}

/* 1 when a facade stands between point p and the sun (street canyon shadows); skip_side: the facade the point
 * is on (-1: none). The pixel loop's shadow test, for one point. */
int64_t rollcam_sun_blocked(const double *restrict world, const int64_t *restrict lut, int64_t n_bins,
                            const double *restrict bld, const double *restrict light, double px, double py,
                            double pz, int64_t skip_side) {
    double sun_x = light[L_SUN], sun_y = light[L_SUN + 1], sun_z = light[L_SUN + 2];
    if (sun_z <= 0.0)
        return 1;
    if (sun_x == 0.0)
        return 0;
    int side = sun_x > 0.0 ? 1 : 0;
    if (side == skip_side)
        return 0;
    double xf = world[W_FACADE];
    double t = ((side == 1 ? xf : -xf) - px) / sun_x;
    if (t <= 0.0)
        return 0;
    int64_t b = building_at(lut, (int32_t)n_bins, side, py + t * sun_y, world);
    return pz + t * sun_z < bld[b * BLD_COLS + B_HEIGHT];
}

/* What a line's pixels need from the scene, its camera and its pose: the constants of every pixel loop. */
struct line_ctx {
    int transposed;
    int32_t n_bins, stride;
    double line, inv_fx, inv_fy, cx0, cy0, px, py, pz;
    double r00, r01, r02, r10, r11, r12, r20, r21, r22;
    double xf, y_half, period, inv_period, inv_bin, road, curb, cross_y;
    uint32_t seed;
    double sun_x, sun_y, sun_z, sun_up, sun_xf, inv_fog, glow_emit, fog_max;
    int sun_side;
    double amb[3], sun_rgb[3], haze[3], hor[3], zen[3], asph[3], walk[3];
};

/* Pixel classes: what its ray hits first (the road's asphalt, or the curb and sidewalk beside it). */
enum { HIT_SKY = 0, HIT_ASPHALT = 1, HIT_SIDEWALK = 2, HIT_WALL = 3 };
/* Pixels classified at a time: the hit pass's scratch stays in the L1 cache. */
#define BLOCK 256

/* The ray direction (unnormalised, world frame) of pixel a of the line. */
static inline __attribute__((always_inline)) void ray_dir(const struct line_ctx *restrict k, int32_t a, double *dx,
                                                          double *dy, double *dz) {
    double xi = k->transposed ? k->line : (double)a, yi = k->transposed ? (double)a : k->line;
    double cx = (xi + 0.5 - k->cx0) * k->inv_fx, cy = (yi + 0.5 - k->cy0) * k->inv_fy;
    *dx = cx * k->r00 + cy * k->r10 + k->r20;
    *dy = cx * k->r01 + cy * k->r11 + k->r21;
    *dz = cx * k->r02 + cy * k->r12 + k->r22;
}

/* The sun's light on hit point h of normal dot sun `ndotl` (0 in a facade's shadow); on_sun_facade: the point
 * is on the facade the shadow probe starts from, which cannot shade it. */
static inline __attribute__((always_inline)) double sun_light(const struct line_ctx *restrict k,
                                                              const int64_t *restrict lut,
                                                              const double *restrict bld, double hx, double hy,
                                                              double hz, double ndotl, flag on_sun_facade) {
    double ts = (k->sun_xf - hx) / k->sun_x;
    int32_t bin_s = street_bin(hy + ts * k->sun_y, k->y_half, k->inv_period, k->inv_bin, k->n_bins);
    int64_t b_s = lut[k->sun_side * k->stride + bin_s];
    double h_s = bld[b_s * BLD_COLS + B_HEIGHT];
    flag probe = !on_sun_facade & (ts > 0.0);
    flag shadow = probe & (hz + ts * k->sun_z < h_s);
    double lit = ndotl > 0.0 ? ndotl : 0.0;
    lit = shadow ? 0.0 : lit;
    return lit * k->sun_up; /* (sun_x == 0 or sun_z <= 0 hold for the whole line: see sun_up) */
}

/* The fog's transmittance along the ray to a hit at t. */
static inline __attribute__((always_inline)) double fog_at(const struct line_ctx *restrict k,
                                                           const double *restrict fog, double t, double dx,
                                                           double dy, double dz) {
    double dist = t * sqrt(dx * dx + dy * dy + dz * dz);
    return fog_transmittance(dist * k->inv_fog, fog, k->fog_max);
}

/* Classify pixels a0..a0+m: the class, the hit distance and the building row (on a facade; -1 elsewhere) of
 * each. */
static inline __attribute__((always_inline)) void hit_pass(const struct line_ctx *restrict k,
                                                           const int64_t *restrict lut,
                                                           const double *restrict bld, int32_t a0, int32_t m,
                                                           int64_t *restrict cls, double *restrict t_out,
                                                           int64_t *restrict b_out) {
#pragma omp simd
    for (int32_t j = 0; j < m; j++) {
        /* Conditions combine with & and | (not && and ||) and values by selection, so the loop body has no
         * branch for the vectoriser to give up on; every table read is at a valid (clamped) index. */
        double dx, dy, dz;
        ray_dir(k, a0 + j, &dx, &dy, &dz);
        double t_ground = -k->pz / dz;
        flag ground = (dz < 0.0) & (k->pz > 0.0) & (fabs(k->px + t_ground * dx) < k->xf);
        double t_hit = ground ? t_ground : 1e30;
        flag side = dx > 0.0 ? 1 : 0;
        double t_wall = ((side == 1 ? k->xf : -k->xf) - k->px) / dx;
        double fz_w = k->pz + t_wall * dz;
        int32_t bin_w = street_bin(k->py + t_wall * dy, k->y_half, k->inv_period, k->inv_bin, k->n_bins);
        int64_t b_w = lut[side * k->stride + bin_w];
        double top = bld[b_w * BLD_COLS + B_HEIGHT];
        flag wall = (dx != 0.0) & (t_wall > 0.0) & (t_wall < t_hit) & (fz_w >= 0.0) & (fz_w < top);
        t_hit = wall ? t_wall : t_hit;
        flag asphalt = fabs(clampc(k->px + t_hit * dx)) < k->road;
        t_out[j] = t_hit;
        b_out[j] = wall ? b_w : -1;
        cls[j] = wall ? HIT_WALL : (ground ? (asphalt ? HIT_ASPHALT : HIT_SIDEWALK) : HIT_SKY);
    }
}

/* Sky pixels a0..a1: the horizon-to-zenith blend and the sun's glow. */
static inline __attribute__((always_inline)) void shade_sky(const struct line_ctx *restrict k,
                                                            const double *restrict light, int32_t a0, int32_t a1,
                                                            float *restrict out) {
#pragma omp simd
    for (int32_t a = a0; a < a1; a++) {
        double dx, dy, dz, s_sky, glow;
        ray_dir(k, a, &dx, &dy, &dz);
        sky_weights(dx, dy, dz, light, &s_sky, &glow);
        for (int c = 0; c < 3; c++)
            out[3 * a + c] = (float)(k->hor[c] * (1.0 - s_sky) + k->zen[c] * s_sky + k->sun_rgb[c] * glow);
    }
}

/* Ground pixels a0..a1 (t: their hit distances from a0 on), all on the asphalt (two noises, markings) or all
 * off it (curb; sidewalk: tiles, one noise), lit by the sun and the sky, through the fog. */
static inline __attribute__((always_inline)) void shade_ground(const struct line_ctx *restrict k,
                                                               const int64_t *restrict lut,
                                                               const double *restrict bld,
                                                               const double *restrict fog, int32_t a0, int32_t a1,
                                                               const double *restrict t, const int asphalt,
                                                               float *restrict out) {
    static const double paint_rgb[3] = {0.62, 0.62, 0.60}, curb_rgb[3] = {0.45, 0.44, 0.42};
    const double inv_tile = 1.0 / 0.6;
#pragma omp simd
    for (int32_t a = a0; a < a1; a++) {
        double dx, dy, dz;
        ray_dir(k, a, &dx, &dy, &dz);
        double t_hit = t[a - a0];
        double hx = clampc(k->px + t_hit * dx), hy = clampc(k->py + t_hit * dy), hz = clampc(k->pz + t_hit * dz);
        double ax = fabs(hx);
        double alb[3];
        if (asphalt) {
            double gm = (hx + 100.0) - floor(hx + 100.0);
            double cm = hy - floor(hy * (1.0 / 9.0)) * 9.0;
            flag zebra_zone = (fabs(hy - k->cross_y) < 2.0) & (ax < k->road - 0.3);
            flag centre = ax < 0.07, edge = (k->road - 0.35 < ax) & (ax < k->road - 0.2);
            flag paint = zebra_zone ? gm < 0.5 : (centre ? cm < 3.0 : edge);
            double noise_a = value_noise(hx * 9.0, hy * 9.0, k->seed);
            double noise_b = value_noise(hx * 1.3, hy * 1.3, k->seed + 7u); /* coarse asphalt grain */
            double g_asph = 0.75 + 0.5 * (noise_a * 0.6 + noise_b * 0.4);
            for (int c = 0; c < 3; c++)
                alb[c] = paint ? paint_rgb[c] : k->asph[c] * g_asph;
        } else {
            flag kerb = ax < k->curb;
            double tu = (ax - k->curb) * inv_tile, tv = hy * inv_tile;
            double tiu = floor(tu), tiv = floor(tv);
            /* one mask, not an | of two masks: the form gcc vectorises */
            double grout_d = tu - tiu < tv - tiv ? tu - tiu : tv - tiv;
            flag grout = grout_d < 0.04;
            double noise_a = value_noise(hx * 4.0, hy * 4.0, k->seed + 11u);
            double cell = hash01((int32_t)tiu, (int32_t)tiv, k->seed + 3u);
            double g_walk = (0.85 + 0.3 * cell) * (grout ? 0.7 : 1.0) * (0.9 + 0.2 * noise_a);
            for (int c = 0; c < 3; c++)
                alb[c] = kerb ? curb_rgb[c] : k->walk[c] * g_walk;
        }
        double lit = sun_light(k, lut, bld, hx, hy, hz, k->sun_z, 0);
        double f = fog_at(k, fog, t_hit, dx, dy, dz);
        double g = 1.0 - f;
        for (int c = 0; c < 3; c++)
            out[3 * a + c] = (float)((alb[c] * (k->amb[c] + k->sun_rgb[c] * lit + 0.0)) * f + k->haze[c] * g);
    }
}

/* The share of [x - h, x + h] that a periodic pulse covers (period p, on over [k p, k p + w) for every
 * integer k): the pulse box-filtered over a pixel's footprint 2h on the surface, so that mortar joints and
 * mullions thinner than a pixel shade it by their area instead of aliasing. */
static inline __attribute__((always_inline)) double pulse_cover(double x, double h, double p, double w) {
    double lo = x - h, hi = x + h;
    double klo = floor(lo / p), khi = floor(hi / p);
    double rlo = lo - klo * p, rhi = hi - khi * p;
    double c_lo = klo * w + (rlo < w ? rlo : w), c_hi = khi * w + (rhi < w ? rhi : w);
    return (c_hi - c_lo) / (hi - lo);
}

/* Schlick's Fresnel reflectance of glass of normal reflectance r0 at incidence cosine `cosi`. */
static inline __attribute__((always_inline)) double fresnel(double r0, double cosi) {
    double m = 1.0 - cosi, m2 = m * m;
    return r0 + (1.0 - r0) * (m2 * m2 * m);
}

/* Normal reflectance of a window pane and of a curtain wall's coated glass. */
#define GLASS_R0 0.06
#define COATED_R0 0.2

/* Facade pixels a0..a1 of building row b_w (t: their hit distances from a0 on), all of material `mat` (a
 * constant argument: one loop per material): the wall (plaster grain, brick courses in running bond or ashlar
 * blocks, their joints filtered over the pixel's footprint; a curtain wall's mullions), floors, window columns,
 * shop fronts and lit windows, lit by the sun and the sky, through the fog. Glass (panes, shop windows, the
 * curtain wall) reflects what the mirrored ray meets: the facade across the street (its colour in the ambient
 * light and half the sun's), the ground, or the sky, by Schlick's Fresnel term. */
static inline __attribute__((always_inline)) void shade_wall(const struct line_ctx *restrict k,
                                                             const int64_t *restrict lut,
                                                             const double *restrict bld,
                                                             const double *restrict light,
                                                             const double *restrict fog, int32_t a0, int32_t a1,
                                                             const double *restrict t, int64_t b_w, const int mat,
                                                             float *restrict out) {
    static const double door_rgb[3] = {0.0, 0.08, 0.06};
    /* brick (course and length with their joint, joint width) and ashlar (the same), metres */
    const double course = mat == MAT_BRICK ? 0.075 : 0.36, unit = mat == MAT_BRICK ? 0.225 : 0.72;
    const double joint = mat == MAT_BRICK ? 0.011 : 0.012, tint_amp = mat == MAT_BRICK ? 0.28 : 0.14;
    const double mullion = 0.09;
    /* the building's values, as locals (no gathers) */
    const double *restrict row = bld + b_w * BLD_COLS;
    const double y0 = row[B_Y0], floor_h = row[B_FLOOR], win_sp = row[B_WIN_SP], win_w = row[B_WIN_W];
    const double top = row[B_HEIGHT], lit_share = row[B_LIT];
    double rgb[3], win_rgb[3], joint_rgb[3];
    for (int c = 0; c < 3; c++) {
        rgb[c] = row[B_RGB + c], win_rgb[c] = row[B_WIN_RGB + c];
        joint_rgb[c] = mat == MAT_BRICK ? 0.46 - 0.02 * c : 0.75 * row[B_RGB + c];
    }
    const uint32_t seed_b = k->seed + (uint32_t)b_w * 131u;
    const double margin = 0.5 * (win_sp - win_w);
    const double r0 = mat == MAT_GLASS ? COATED_R0 : GLASS_R0;
#pragma omp simd
    for (int32_t a = a0; a < a1; a++) {
        double dx, dy, dz;
        ray_dir(k, a, &dx, &dy, &dz);
        double t_hit = t[a - a0];
        flag side = dx > 0.0 ? 1 : 0;
        double hx = clampc(k->px + t_hit * dx), hy = clampc(k->py + t_hit * dy), hz = clampc(k->pz + t_hit * dz);
        double u = hy + k->y_half;
        u -= floor(u * k->inv_period) * k->period;
        u -= k->y_half + y0;
        /* half the pixel's footprint on the wall along u and z (the ray's Jacobian on the plane x = const) */
        double inv_dx = 1.0 / dx;
        double hu = 0.5 * fabs(t_hit) * (fabs(k->r01 - dy * k->r00 * inv_dx) * k->inv_fx
                                         + fabs(k->r11 - dy * k->r10 * inv_dx) * k->inv_fy) + 1e-6;
        double hv = 0.5 * fabs(t_hit) * (fabs(k->r02 - dz * k->r00 * inv_dx) * k->inv_fx
                                         + fabs(k->r12 - dz * k->r10 * inv_dx) * k->inv_fy) + 1e-6;
        double floor_i = floor(hz / floor_h);
        double zz = hz - floor_i * floor_h;
        double col_i = floor(u / win_sp);
        double uu = u - col_i * win_sp;
        double noise_a = value_noise(u * 3.0, hz * 3.0, seed_b);
        double cell = hash01((int32_t)col_i, floor_i == 0.0 ? 17 : (int32_t)floor_i, seed_b);
        double grain = mat == MAT_STONE ? 0.82 + 0.36 * noise_a : 0.9 + 0.2 * noise_a;
        flag cornice = hz > top - 0.6;
        flag ground_floor = floor_i == 0.0;
        flag shop = (!cornice) & ground_floor & (0.1 < zz) & (zz < 2.7) & (0.25 < uu) & (uu < win_sp - 0.25);
        flag door = shop & (cell < 0.35);
        flag window, frame;
        double wall_k = 1.0, joint_w = 0.0;
        if (mat == MAT_GLASS) {
            /* panes of one window spacing by one floor in mullions, from the first floor to the cornice */
            window = (!cornice) & (!ground_floor);
            double m_u = pulse_cover(uu, hu, win_sp, mullion), m_z = pulse_cover(zz, hv, floor_h, mullion);
            joint_w = 1.0 - (1.0 - m_u) * (1.0 - m_z);
            frame = 0;
        } else {
            window = (!cornice) & (!ground_floor) & (0.9 < zz) & (zz < 2.5) & (margin < uu) & (uu < win_sp - margin);
            frame = window & ((zz < 1.0) | (zz > 2.4) | (uu < margin + 0.06) | (uu > win_sp - margin - 0.06));
            if (mat != MAT_PLASTER) {
                /* courses in running bond: every other course shifted by half a unit */
                double course_i = floor(hz / course);
                double shift = (course_i - 2.0 * floor(0.5 * course_i)) * 0.5 * unit;
                double us = u + shift;
                double unit_i = floor(us / unit);
                double m_z = pulse_cover(hz, hv, course, joint), m_u = pulse_cover(us, hu, unit, joint);
                joint_w = 1.0 - (1.0 - m_u) * (1.0 - m_z);
                /* each unit's own tint, faded where a pixel covers many */
                double fade = 1.0 - 2.0 * hv / course;
                fade = fade > 0.0 ? fade : 0.0;
                wall_k = 1.0 + tint_amp * fade * (hash01((int32_t)unit_i, (int32_t)course_i, seed_b + 5u) - 0.5);
            }
        }
        flag pane = (window & !frame) | (shop & !door);
        double wk = 0.7 + 0.6 * cell, k_wall = cornice ? 0.75 : 1.0;
        double emit = (window & (cell < lit_share)) ? k->glow_emit : 0.0;
        double lit = sun_light(k, lut, bld, hx, hy, hz, side == 1 ? -k->sun_x : k->sun_x, side == k->sun_side);
        double f = fog_at(k, fog, t_hit, dx, dy, dz);
        double g = 1.0 - f;
        /* the mirrored ray (dx -> -dx) from the hit: across the street to the other facade, the ground, or the
         * sky */
        double n_d = sqrt(dx * dx + dy * dy + dz * dz);
        double refl = pane ? fresnel(r0, fabs(dx) / n_d) : 0.0;
        double t_o = 2.0 * k->xf * fabs(inv_dx);
        double z_o = hz + t_o * dz;
        int32_t bin_o = street_bin(hy + t_o * dy, k->y_half, k->inv_period, k->inv_bin, k->n_bins);
        int64_t b_o = lut[(1 - side) * k->stride + bin_o];
        flag hit_o = (z_o >= 0.0) & (z_o < bld[b_o * BLD_COLS + B_HEIGHT]);
        flag hit_g = (z_o < 0.0) & (dz < 0.0);
        double s_sky, glow;
        sky_weights(-dx, dy, dz, light, &s_sky, &glow);
        double sun_o = 0.5 * fabs(k->sun_x) * k->sun_up;
        for (int c = 0; c < 3; c++) {
            double w_c = rgb[c] * grain * k_wall * wall_k;
            w_c = w_c + (joint_rgb[c] - w_c) * joint_w;
            double shop_c = door ? (c == 0 ? 0.12 + 0.2 * cell : door_rgb[c]) : win_rgb[c] * 0.8;
            double win_c = win_rgb[c] * wk;
            win_c = frame ? win_c * 0.5 + 0.1 : win_c;
            win_c = mat == MAT_GLASS ? win_c + (rgb[c] - win_c) * joint_w : win_c;
            double alb = window ? win_c : (shop ? shop_c : w_c);
            double env_o = bld[b_o * BLD_COLS + B_RGB + c] * (k->amb[c] + k->sun_rgb[c] * sun_o);
            double env_s = k->hor[c] * (1.0 - s_sky) + k->zen[c] * s_sky + k->sun_rgb[c] * glow;
            double env = hit_o ? env_o : (hit_g ? k->asph[c] * k->amb[c] : env_s);
            double r_c = mat == MAT_GLASS ? refl * (1.0 - joint_w) : refl;
            out[3 * a + c] = (float)(((alb * (1.0 - r_c)) * (k->amb[c] + k->sun_rgb[c] * lit + emit) + r_c * env) * f
                                     + k->haze[c] * g);
        }
    }
}

/* Facade pixels a0..a1 of building row b_w, by its material (each material's loop apart). */
static inline __attribute__((always_inline)) void shade_facade(const struct line_ctx *restrict k,
                                                               const int64_t *restrict lut,
                                                               const double *restrict bld,
                                                               const double *restrict light,
                                                               const double *restrict fog, int32_t a0, int32_t a1,
                                                               const double *restrict t, int64_t b_w,
                                                               float *restrict out) {
    switch ((int)bld[b_w * BLD_COLS + B_MAT]) {
    case MAT_BRICK: shade_wall(k, lut, bld, light, fog, a0, a1, t, b_w, MAT_BRICK, out); break;
    case MAT_STONE: shade_wall(k, lut, bld, light, fog, a0, a1, t, b_w, MAT_STONE, out); break;
    case MAT_GLASS: shade_wall(k, lut, bld, light, fog, a0, a1, t, b_w, MAT_GLASS, out); break;
    default: shade_wall(k, lut, bld, light, fog, a0, a1, t, b_w, MAT_PLASTER, out); break;
    }
}

/* Surfaces a background pixel's ray can hit, for rollcam_background_span's `surface` output: the sky (at
 * infinity), the ground plane z = 0 (asphalt, curb and sidewalk) and the west (x = -W_FACADE) and east
 * (x = +W_FACADE) facade planes. A moving camera's background blur maps each pixel through its surface's plane
 * (rollcam.sim.render.egoblur). A flat or chart scene has no geometry: its pixels say SURF_SKY. */
enum { SURF_SKY = 0, SURF_GROUND = 1, SURF_WEST = 2, SURF_EAST = 3 };

/* Pixels a_begin..a_end - 1 of one render-space line of the background from pose (rot, pos), linear RGB into
 * out[3 a ..] (out is addressed by pixel index), and when `surface` is not NULL each pixel's surface into
 * surface[a]. Blocks of pixels are classified by what their rays hit, and each run of one class is shaded by its
 * material's loop alone (a street line is a few long runs of sky, facades and ground). */
static inline __attribute__((always_inline)) void background_range(
    const double *restrict world, const int64_t *restrict lut, int64_t n_bins64, const double *restrict bld,
    const double *restrict light, const double *restrict cam, const double *restrict rot,
    const double *restrict pos, double line, int32_t a_begin, int32_t a_end, float *restrict out,
    int8_t *restrict surface) {
    int kind = (int)world[W_KIND];
    if (kind != KIND_STREET) {
        /* A flat level, or a chart's uniform matte board filling the view. */
        for (int32_t a = a_begin; a < a_end; a++) {
            for (int c = 0; c < 3; c++)
                out[3 * a + c] = (float)(kind == KIND_FLAT ? world[W_LEVEL] : world[W_ASPHALT + c]);
            if (surface)
                surface[a] = SURF_SKY;
        }
        return;
    }
    struct line_ctx k;
    k.n_bins = (int32_t)n_bins64, k.stride = k.n_bins + 1;
    k.transposed = cam[C_TRANSPOSED] != 0.0;
    k.line = line;
    k.inv_fx = 1.0 / cam[C_FX], k.inv_fy = 1.0 / cam[C_FY], k.cx0 = cam[C_CX], k.cy0 = cam[C_CY];
    k.px = pos[0], k.py = pos[1], k.pz = pos[2];
    k.r00 = rot[0], k.r01 = rot[1], k.r02 = rot[2], k.r10 = rot[3], k.r11 = rot[4], k.r12 = rot[5];
    k.r20 = rot[6], k.r21 = rot[7], k.r22 = rot[8];
    k.xf = world[W_FACADE], k.y_half = world[W_YHALF];
    k.period = 2.0 * k.y_half, k.inv_period = 1.0 / k.period, k.inv_bin = 1.0 / world[W_BIN];
    k.seed = (uint32_t)(int64_t)world[W_SEED];
    k.road = world[W_ROAD], k.curb = world[W_ROAD] + world[W_CURB], k.cross_y = world[W_CROSS];
    k.sun_x = light[L_SUN], k.sun_y = light[L_SUN + 1], k.sun_z = light[L_SUN + 2];
    k.inv_fog = 1.0 / light[L_FOG], k.glow_emit = light[L_GLOW];
    k.sun_side = k.sun_x > 0.0 ? 1 : 0;
    /* The sun's conditions that hold for the whole line, as a factor of the loop (a condition taken from
     * outside the loop into its masks stops gcc vectorising it): 0 below the horizon; with sun_x == 0 no
     * facade can shade (the probe's ts is then infinite). */
    k.sun_up = k.sun_z <= 0.0 ? 0.0 : 1.0;
    k.sun_xf = k.sun_side == 1 ? k.xf : -k.xf;
    /* Table values the loops read, as locals: a table read under a condition becomes a masked load gcc cannot
     * vectorise. */
    for (int c = 0; c < 3; c++) {
        k.asph[c] = world[W_ASPHALT + c], k.walk[c] = world[W_SIDEWALK + c];
        k.amb[c] = light[L_AMB + c], k.sun_rgb[c] = light[L_SUN_RGB + c], k.haze[c] = light[L_HAZE + c];
        k.hor[c] = light[L_HORIZON + c], k.zen[c] = light[L_ZENITH + c];
    }
    k.fog_max = fog_x_max;
    const double *restrict fog = fog_table; /* a pointer: gcc gathers from it, not from the global */
    int64_t cls[BLOCK], b_hit[BLOCK];
    double t_hit[BLOCK];
    for (int32_t a0 = a_begin; a0 < a_end; a0 += BLOCK) {
        int32_t m = a_end - a0 < BLOCK ? a_end - a0 : BLOCK;
        hit_pass(&k, lut, bld, a0, m, cls, t_hit, b_hit);
        if (surface) {
            for (int32_t j = 0; j < m; j++) {
                double dx, dy, dz;
                ray_dir(&k, a0 + j, &dx, &dy, &dz);
                surface[a0 + j] = (int8_t)(cls[j] == HIT_SKY ? SURF_SKY
                                           : cls[j] == HIT_WALL ? (dx > 0.0 ? SURF_EAST : SURF_WEST) : SURF_GROUND);
            }
        }
        for (int32_t j = 0; j < m;) { /* the runs of one class (and on a facade, of one building) */
            int32_t e = j + 1;
            while (e < m && cls[e] == cls[j] && b_hit[e] == b_hit[j])
                e++;
            if (cls[j] == HIT_SKY)
                shade_sky(&k, light, a0 + j, a0 + e, out);
            else if (cls[j] == HIT_WALL)
                shade_facade(&k, lut, bld, light, fog, a0 + j, a0 + e, t_hit + j, b_hit[j], out);
            else if (cls[j] == HIT_ASPHALT) /* (a constant argument: one loop without the branch for each) */
                shade_ground(&k, lut, bld, fog, a0 + j, a0 + e, t_hit + j, 1, out);
            else
                shade_ground(&k, lut, bld, fog, a0 + j, a0 + e, t_hit + j, 0, out);
            j = e;
        }
    }
}

/* One render-space line of the background from pose (rot, pos): `n` pixels of linear RGB into out (n x 3). */
CLONES
void rollcam_background_line(const double *restrict world, const int64_t *restrict lut, int64_t n_bins64,
                             const double *restrict bld, const double *restrict light, const double *restrict cam,
                             const double *restrict rot, const double *restrict pos, int64_t line,
                             float *restrict out, int64_t n) {
    background_range(world, lut, n_bins64, bld, light, cam, rot, pos, (double)line, 0, (int32_t)n, out, NULL);
}

/* Pixels a_begin..a_end - 1 of render-space line `line` (any pixel or line index, inside the image or beyond
 * it: the blur's margins) from pose (rot, pos): linear RGB into out[3 (a - a_begin) ..], and each pixel's
 * SURF_ code into surface[a - a_begin] when `surface` is not NULL. The same IEEE operations as
 * rollcam_background_line for the same pixel. */
CLONES
void rollcam_background_span(const double *restrict world, const int64_t *restrict lut, int64_t n_bins64,
                             const double *restrict bld, const double *restrict light, const double *restrict cam,
                             const double *restrict rot, const double *restrict pos, double line, int64_t a_begin,
                             int64_t a_end, float *restrict out, int8_t *restrict surface) {
    /* Pointers addressed by pixel index (a_begin may be negative), kept as integers until the shift. */
    float *o = (float *)((uintptr_t)out - (uintptr_t)(3 * a_begin * (int64_t)sizeof(float)));
    int8_t *s = surface ? (int8_t *)((uintptr_t)surface - (uintptr_t)a_begin) : NULL;
    background_range(world, lut, n_bins64, bld, light, cam, rot, pos, line, (int32_t)a_begin, (int32_t)a_end, o, s);
}

/* A moving camera's background blur for one render line (rollcam.sim.render.egoblur): acc[a] (n_along x 3 doubles) gets
 * the sum over the line's n time samples of the bilinear read of `bg` (a float32 frame of n_rows x n_cols x 3,
 * the background with margins) at where the mid-exposure pose sees pixel a's ray at sample j through its
 * surface's plane. coef[(j * 4 + s) * 6 ..] = (x0, x1, y0, y1, z0, z1): image position ((x0 + a x1) / z,
 * (y0 + a y1) / z), z = z0 + a z1; slot u_slot maps from dt_u seconds before mid-exposure, for the image velocity
 * behind the rolling-shutter correction (lt: seconds per render line). surf: pixel a's surface code; scratch:
 * 2 n_along doubles. Reads are clamped to the frame. */
CLONES
void rollcam_path_reads(const float *restrict bg, int64_t n_rows, int64_t n_cols, const int8_t *restrict surf,
                        const double *restrict coef, int64_t n, int64_t u_slot, double ln, double lt, double dt_u,
                        int64_t transposed, int64_t margin, int64_t n_along, double *restrict scratch,
                        double *restrict acc) {
    double *restrict d_inv = scratch, *restrict k_a = scratch + n_along;
    const double row_max = (double)(n_rows - 1), col_max = (double)(n_cols - 1);
    const int64_t row_hi = n_rows - 2, col_hi = n_cols - 2, row = n_cols * 3;
    const double m = (double)margin;
    for (int64_t a = 0; a < n_along; a++) {
        const double *restrict c = coef + (u_slot * 4 + surf[a]) * 6;
        double z = c[4] + a * c[5];
        z = z > 1e-9 ? z : 1e-9;
        double x = (c[0] + a * c[1]) / z, y = (c[2] + a * c[3]) / z;
        double u_l = ((transposed ? x : y) - ln) / dt_u, u_a = ((transposed ? y : x) - (double)a) / dt_u;
        double den = 1.0 - u_l * lt;
        den = den > 0.1 ? den : 0.1; /* (u_l lt is a few percent at most: a line time is microseconds) */
        d_inv[a] = 1.0 / den;
        k_a[a] = u_a * lt / den;
        acc[3 * a] = 0.0, acc[3 * a + 1] = 0.0, acc[3 * a + 2] = 0.0;
    }
    for (int64_t j = 0; j < n; j++) {
        const double *restrict cj = coef + j * 4 * 6;
#pragma omp simd
        for (int64_t a = 0; a < n_along; a++) {
            const double *restrict c = cj + surf[a] * 6;
            double z = c[4] + a * c[5];
            flag ok = z > 1e-9; /* behind the camera: read the pixel itself */
            double zz = ok ? z : 1.0;
            double x = (c[0] + a * c[1]) / zz, y = (c[2] + a * c[3]) / zz;
            double d_l = ok ? (transposed ? x : y) - ln : 0.0;
            double pa = ok ? (transposed ? y : x) : (double)a;
            double li = ln + d_l * d_inv[a] + m, ai = pa + k_a[a] * d_l + m;
            li = li > 0.0 ? (li < row_max ? li : row_max) : 0.0;
            ai = ai > 0.0 ? (ai < col_max ? ai : col_max) : 0.0;
            int64_t i0 = (int64_t)li, k0 = (int64_t)ai;
            i0 = i0 < row_hi ? i0 : row_hi;
            k0 = k0 < col_hi ? k0 : col_hi;
            double fl = li - (double)i0, fa = ai - (double)k0;
            const float *restrict p = bg + i0 * row + k0 * 3;
            for (int ch = 0; ch < 3; ch++) {
                double top = p[ch] + fa * (p[3 + ch] - p[ch]);
                double bot = p[row + ch] + fa * (p[row + 3 + ch] - p[row + ch]);
                acc[3 * a + ch] += top + fl * (bot - top);
            }
        }
    }
}

/* Linear RGB pixels (n x 3 float32) to 8-bit BGR through the output curve `lut` (lut_size + 1 entries): scaled by
 * gain, clipped to [0, 1] (NaN to 0), and looked up at the nearest of its lut_size steps. The renderer's one
 * encoder (rollcam.sim.render.lines.encode_line): gcc vectorises it (the per-pixel loop in numba was scalar and cost
 * about a fifth of a moving-camera frame). */
CLONES
void rollcam_encode_line(const float *restrict lin, double gain, const uint8_t *restrict lut, int64_t lut_size,
                         uint8_t *restrict out, int64_t n) {
    const double scale = (double)lut_size;
    int32_t idx[3 * 256]; /* a block's table indices: the vectorised part (gcc will not gather bytes) */
    for (int64_t a0 = 0; a0 < n; a0 += 256) {
        const int32_t m = (int32_t)(3 * (n - a0 < 256 ? n - a0 : 256));
        const float *restrict src = lin + 3 * a0;
        for (int32_t k = 0; k < m; k++) {
            double v = (double)src[k] * gain;
            v = v > 0.0 ? (v < 1.0 ? v : 1.0) : 0.0;
            idx[k] = (int32_t)(v * scale + 0.5);
        }
        uint8_t *restrict dst = out + 3 * a0;
        for (int32_t k = 0; k < m; k += 3) { /* RGB in, BGR out */
            dst[k] = lut[idx[k + 2]];
            dst[k + 1] = lut[idx[k + 1]];
            dst[k + 2] = lut[idx[k]];
        }
    }
}

/* The fog and the noise for one point, for the tests. */
double rollcam_fog_transmittance(double x) { return fog_transmittance(x, fog_table, fog_x_max); }

double rollcam_value_noise(double x, double y, int64_t seed) { return value_noise(x, y, (uint32_t)seed); }

double rollcam_pulse_cover(double x, double h, double p, double w) { return pulse_cover(x, h, p, w); }

/* The table columns this library reads, for the loader to check against rollcam/sim/render/world.py. */
int64_t rollcam_shade_layout(int64_t *out, int64_t n) {
    static const int64_t cols[] = {C_FX, C_FY, C_CX, C_CY, C_TRANSPOSED, L_SUN, L_SUN_RGB, L_AMB, L_HORIZON,
                                   L_ZENITH, L_HAZE, L_FOG, L_GLOW, W_KIND, W_ROAD, W_CURB, W_FACADE, W_YHALF,
                                   W_ASPHALT, W_SIDEWALK, W_CROSS, W_SEED, W_LEVEL, W_BIN, KIND_STREET, KIND_FLAT,
                                   B_Y0, B_HEIGHT, B_RGB, B_WIN_RGB, B_FLOOR, B_WIN_W, B_WIN_SP, B_LIT, B_MAT,
                                   BLD_COLS, MAT_PLASTER, MAT_BRICK, MAT_STONE, MAT_GLASS};
    int64_t m = (int64_t)(sizeof cols / sizeof cols[0]);
    for (int64_t i = 0; i < n && i < m; i++)
        out[i] = cols[i];
    return m;
}
