/*
 * The coarse reflectance map's inner loops, compiled: angles and cells of LAS point records in one pass,
 * and a chunk's per-cell sums.
 *
 * Every operation repeats, in the same order and precision, what lidar.reflectance_map and
 * lidar.angles.spherical32 do with numpy, so the map is the same to the bit with or without this library
 * (tested). Build with -ffp-contract=off: a fused multiply-add rounds once where numpy rounds twice.
 * Little-endian hosts only (LAS is little-endian; the loader refuses others).
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#ifndef BS_SOURCE_DIGEST
#define BS_SOURCE_DIGEST "unknown"
#endif

/* The first 16 hex digits of this file's SHA-256 when it was built (setup.py): a library built from another
 * version of the source is left unused. */
const char *bs_source_digest(void) { return BS_SOURCE_DIGEST; }

/* degrees(atan2(y, x)) as lidar.angles.atan2_deg32: a polynomial in the smaller over the larger of |x|, |y|
 * (coefficients c[0..6], degrees), the octant restored by sign arithmetic. */
static inline float atan2_deg(float y, float x, const float *c)
{
    float ax = fabsf(x), ay = fabsf(y);
    float big = ax > ay ? ax : ay;
    big = big > 1e-30f ? big : 1e-30f;
    float a = (ax < ay ? ax : ay) / big;
    float s = a * a;
    float r = s * c[6];
    for (int k = 5; k >= 1; --k) {
        r += c[k];
        r *= s;
    }
    r += c[0];
    r *= a;
    float t = 45.0f - r; /* 90 - r where |y| > |x| */
    t *= copysignf(1.0f, ax - ay);
    r = 45.0f - t;
    t = 90.0f - r; /* 180 - r where x < 0 */
    t *= copysignf(1.0f, x);
    r = 90.0f - t;
    return copysignf(r, y);
}

/* Zenith angle, azimuth in [0, 360] and range, as lidar.angles.spherical32. */
static inline void spherical(float x, float y, float z, const float *c, float *theta, float *phi, float *range)
{
    float p = atan2_deg(y, x, c);
    p += (float)(p < 0.0f) * 360.0f;
    float h = x * x;
    h += y * y;
    float rr = z * z;
    rr += h;
    *phi = p;
    *theta = atan2_deg(sqrtf(h), z, c);
    *range = sqrtf(rr);
}

/* A record's coordinates in float32: scaled in double and rounded once, as the LAS reader scales them. */
static inline void record_xyz(const uint8_t *rec, const double *scale, const double *offset, float *xyz)
{
    int32_t v[3];
    memcpy(v, rec, sizeof v);
    for (int k = 0; k < 3; ++k) {
        double d = (double)v[k] * scale[k];
        d += offset[k];
        xyz[k] = (float)d;
    }
}

/* Points are handled in blocks: the records' fields are copied out one by one, then the angles of the block are
 * computed in loops the compiler turns into vector instructions. */
#define BLOCK 256

/* An AVX2 copy of the vector loops beside the baseline one, picked when the program loads (same results: the
 * same operations, eight lanes instead of four, and no fused multiply-add either way). */
#if defined(__GNUC__) && defined(__x86_64__) && defined(__linux__)
#define TARGETS __attribute__((target_clones("avx2", "default")))
#else
#define TARGETS
#endif

/* Coordinates of records 0, step, 2 step, ... (n <= BLOCK of them). */
static inline void block_xyz(const uint8_t *records, int64_t n, int64_t stride, const double *scale,
                             const double *offset, float *x, float *y, float *z)
{
    for (int64_t i = 0; i < n; ++i) {
        float xyz[3];
        record_xyz(records + i * stride, scale, offset, xyz);
        x[i] = xyz[0];
        y[i] = xyz[1];
        z[i] = xyz[2];
    }
}

static inline void block_spherical(int64_t n, const float *x, const float *y, const float *z, const float *coef,
                                   float *theta, float *phi, float *range)
{
    for (int64_t i = 0; i < n; ++i)
        spherical(x[i], y[i], z[i], coef, theta + i, phi + i, range + i);
}

/* Zenith angle and azimuth of records 0, step, 2 step, ... (n of them) of record_length bytes each. */
TARGETS void bs_record_angles(const uint8_t *records, int64_t n, int64_t record_length, int64_t step,
                      const double *scale, const double *offset, const float *coef, float *theta, float *phi)
{
    float x[BLOCK], y[BLOCK], z[BLOCK], r[BLOCK];
    for (int64_t b = 0; b < n; b += BLOCK) {
        int64_t m = n - b < BLOCK ? n - b : BLOCK;
        block_xyz(records + b * step * record_length, m, step * record_length, scale, offset, x, y, z);
        block_spherical(m, x, y, z, coef, theta + b, phi + b, r);
    }
}

/* Cell index (column-major: col * height + row), range and intensity of n records; the grid's rows start at
 * row_lo (absolute rows of step 1 / inv_step) and its columns at azimuth phi0. Writes the smallest and largest
 * cell index to cell_span[0..1] and the intensity range to intensity_span[0..1]. */
TARGETS void bs_record_cells(const uint8_t *records, int64_t n, int64_t record_length, const double *scale,
                     const double *offset, const float *coef, float phi0, float inv_step, int32_t row_lo,
                     int32_t height, int32_t width, int64_t *cell, float *range, float *intensity,
                     int64_t *cell_span, float *intensity_span)
{
    int64_t lo = INT64_MAX, hi = INT64_MIN;
    float ilo = INFINITY, ihi = -INFINITY;
    float x[BLOCK], y[BLOCK], z[BLOCK], t[BLOCK], p[BLOCK];
    for (int64_t b = 0; b < n; b += BLOCK) {
        int64_t m = n - b < BLOCK ? n - b : BLOCK;
        const uint8_t *rec = records + b * record_length;
        block_xyz(rec, m, record_length, scale, offset, x, y, z);
        for (int64_t i = 0; i < m; ++i) {
            uint16_t raw;
            memcpy(&raw, rec + i * record_length + 12, sizeof raw);
            intensity[b + i] = (float)raw;
        }
        block_spherical(m, x, y, z, coef, t, p, range + b);
        for (int64_t i = 0; i < m; ++i) {
            float q = p[i] - phi0;
            q += (float)(q < 0.0f) * 360.0f;
            q -= (float)(q >= 360.0f) * 360.0f;
            int32_t row = (int32_t)(t[i] * inv_step) - row_lo;
            int32_t col = (int32_t)(q * inv_step);
            row = row < 0 ? 0 : (row > height - 1 ? height - 1 : row);
            col = col < 0 ? 0 : (col > width - 1 ? width - 1 : col);
            cell[b + i] = (int64_t)col * height + row;
        }
    }
    for (int64_t i = 0; i < n; ++i) {
        int64_t k = cell[i];
        float v = intensity[i];
        lo = k < lo ? k : lo;
        hi = k > hi ? k : hi;
        ilo = v < ilo ? v : ilo;
        ihi = v > ihi ? v : ihi;
    }
    cell_span[0] = lo;
    cell_span[1] = hi;
    intensity_span[0] = ilo;
    intensity_span[1] = ihi;
}
/* Per-cell count, sums (in double, point by point as numpy's bincount adds them) and maximum intensity of n
 * points whose cells are cell[i] - lo; the outputs hold the cell range and start at zero (max_i at -inf). */
void bs_cell_sums(const int64_t *cell, const float *range, const float *intensity, int64_t n, int64_t lo,
                  int64_t *count, double *sum_i, double *sum_r, float *max_i)
{
    for (int64_t i = 0; i < n; ++i) {
        int64_t k = cell[i] - lo;
        float v = intensity[i];
        count[k] += 1;
        sum_i[k] += (double)v;
        sum_r[k] += (double)range[i];
        max_i[k] = v > max_i[k] ? v : max_i[k];
    }
}

/* Adds a chunk's sums (cells 0..span-1 of a range) into the map's cells: counts to int32 and sums rounded to
 * float32 before they are added, as numpy's astype and in-place addition do; the larger of the maxima. */
void bs_merge(int64_t span, const int64_t *count, const double *sum_i, const double *sum_r, const float *max_i,
              int32_t *acc_count, float *acc_sum_i, float *acc_sum_r, float *acc_max_i)
{
    for (int64_t k = 0; k < span; ++k) {
        acc_count[k] += (int32_t)count[k];
        acc_sum_i[k] += (float)sum_i[k];
        acc_sum_r[k] += (float)sum_r[k];
        acc_max_i[k] = max_i[k] > acc_max_i[k] ? max_i[k] : acc_max_i[k];
    }
}
