/*
 * The coarse reflectance map's inner loops, compiled: the survey of LAS point records (what sets the map's step,
 * azimuth origin and rows), their angles and cells in one pass, and a chunk's per-cell sums.
 *
 * Every operation repeats, in the same order and precision, what lidar.reflectance_map and
 * lidar.angles.spherical32 do with numpy, so the map is the same to the bit with or without this library
 * (tested). Build with -ffp-contract=off: a fused multiply-add rounds once where numpy rounds twice; and with
 * -fno-trapping-math, without which the compiler keeps the comparisons as branches and the cell loop scalar.
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

/* Coordinates in float32 of integers: scaled in double and rounded once, as the LAS reader scales them. */
static inline void scale_coordinates(int64_t n, const int32_t *v, double scale, double offset, float *out)
{
    for (int64_t i = 0; i < n; ++i) {
        double d = (double)v[i] * scale;
        d += offset;
        out[i] = (float)d;
    }
}

/* Points are handled in blocks: the records' fields are copied out one by one, then the angles of the block are
 * computed in loops the compiler turns into vector instructions. */
#define BLOCK 256
#define PREFETCH_RECORDS 256

/* An AVX2 copy of the vector loops beside the baseline one, picked when the program loads (same results: the
 * same operations, eight lanes instead of four, and no fused multiply-add either way). */
#if defined(__GNUC__) && defined(__x86_64__) && defined(__linux__)
#define TARGETS __attribute__((target_clones("avx2", "default")))
#else
#define TARGETS
#endif

/* Coordinates of records 0, step, 2 step, ... (n <= BLOCK of them): the integers copied out one record at a
 * time, then scaled in vector loops. */
static inline void block_xyz(const uint8_t *records, int64_t n, int64_t stride, const double *scale,
                             const double *offset, float *x, float *y, float *z)
{
    int32_t xi[BLOCK], yi[BLOCK], zi[BLOCK];
    for (int64_t i = 0; i < n; ++i) {
        int32_t v[3];
        /* the hardware's prefetcher stops at page boundaries; a hint a few pages ahead keeps the loads streaming
         * (a hint past the end of the mapping is dropped, never a fault) */
        __builtin_prefetch(records + (i + PREFETCH_RECORDS) * stride);
        memcpy(v, records + i * stride, sizeof v);
        xi[i] = v[0];
        yi[i] = v[1];
        zi[i] = v[2];
    }
    scale_coordinates(n, xi, scale[0], offset[0], x);
    scale_coordinates(n, yi, scale[1], offset[1], y);
    scale_coordinates(n, zi, scale[2], offset[2], z);
}

static inline void block_spherical(int64_t n, const float *x, const float *y, const float *z, const float *coef,
                                   float *theta, float *phi, float *range)
{
    for (int64_t i = 0; i < n; ++i)
        spherical(x[i], y[i], z[i], coef, theta + i, phi + i, range + i);
}

/* The survey of records 0, step, 2 step, ... (n of them) of record_length bytes each, added to the arrays, as
 * lidar.reflectance_map._Survey.of_angles makes it: the azimuth's 0.1-degree histogram (3600 bins), the
 * 0.5-degree cells of the sphere that hold a point (360 rows of 720) and the zenith angle's range (theta_span[0..1],
 * inf and -inf to start). */
TARGETS void bs_record_survey(const uint8_t *records, int64_t n, int64_t record_length, int64_t step,
                              const double *scale, const double *offset, const float *coef, int64_t *azimuth_hist,
                              uint8_t *occupied, float *theta_span)
{
    float x[BLOCK], y[BLOCK], z[BLOCK], r[BLOCK], t[BLOCK], p[BLOCK];
    float lo = theta_span[0], hi = theta_span[1];
    for (int64_t b = 0; b < n; b += BLOCK) {
        int64_t m = n - b < BLOCK ? n - b : BLOCK;
        block_xyz(records + b * step * record_length, m, step * record_length, scale, offset, x, y, z);
        block_spherical(m, x, y, z, coef, t, p, r);
        for (int64_t i = 0; i < m; ++i) {
            int32_t bin = (int32_t)(p[i] * 10.0f);
            int32_t row = (int32_t)(t[i] / 0.5f);
            int32_t col = (int32_t)(p[i] / 0.5f);
            bin = bin < 0 ? 0 : (bin > 3599 ? 3599 : bin);
            row = row < 0 ? 0 : (row > 359 ? 359 : row);
            col = col < 0 ? 0 : (col > 719 ? 719 : col);
            azimuth_hist[bin] += 1;
            occupied[row * 720 + col] = 1;
            lo = t[i] < lo ? t[i] : lo;
            hi = t[i] > hi ? t[i] : hi;
        }
    }
    theta_span[0] = lo;
    theta_span[1] = hi;
}

/* Cells (column-major: col * height + row) of n angles on a grid whose rows start at row_lo (absolute rows of
 * step 1 / inv_step) and whose columns start at azimuth phi0, as lidar.reflectance_map._Grid.cells; the cell
 * indices fit in int32 (a map has at most 80 M cells). */
static inline void block_cells(int64_t n, const float *t, const float *p, float phi0, float inv_step, int32_t row_lo,
                               int32_t height, int32_t width, int32_t *cell)
{
    for (int64_t i = 0; i < n; ++i) {
        float q = p[i] - phi0;
        q += q < 0.0f ? 360.0f : 0.0f; /* numpy adds 360 * (q < 0): the same sums */
        q -= q >= 360.0f ? 360.0f : 0.0f;
        int32_t row = (int32_t)(t[i] * inv_step) - row_lo;
        int32_t col = (int32_t)(q * inv_step);
        row = row > 0 ? row : 0;
        row = row < height - 1 ? row : height - 1;
        col = col > 0 ? col : 0;
        col = col < width - 1 ? col : width - 1;
        cell[i] = col * height + row;
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
    int32_t lo = INT32_MAX, hi = INT32_MIN;
    uint16_t ilo = UINT16_MAX, ihi = 0;
    float x[BLOCK], y[BLOCK], z[BLOCK], t[BLOCK], p[BLOCK];
    int32_t c[BLOCK];
    uint16_t raw[BLOCK];
    for (int64_t b = 0; b < n; b += BLOCK) {
        int64_t m = n - b < BLOCK ? n - b : BLOCK;
        const uint8_t *rec = records + b * record_length;
        block_xyz(rec, m, record_length, scale, offset, x, y, z);
        for (int64_t i = 0; i < m; ++i)
            memcpy(raw + i, rec + i * record_length + 12, sizeof raw[0]);
        block_spherical(m, x, y, z, coef, t, p, range + b);
        block_cells(m, t, p, phi0, inv_step, row_lo, height, width, c);
        for (int64_t i = 0; i < m; ++i) {
            cell[b + i] = c[i];
            intensity[b + i] = (float)raw[i];
            lo = c[i] < lo ? c[i] : lo;
            hi = c[i] > hi ? c[i] : hi;
            ilo = raw[i] < ilo ? raw[i] : ilo;
            ihi = raw[i] > ihi ? raw[i] : ihi;
        }
    }
    cell_span[0] = n > 0 ? lo : INT64_MAX;
    cell_span[1] = n > 0 ? hi : INT64_MIN;
    intensity_span[0] = n > 0 ? (float)ilo : INFINITY;
    intensity_span[1] = n > 0 ? (float)ihi : -INFINITY;
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

static inline float clip01(float v) { return v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v); } /* NaN stays NaN */

/* Finishes columns col0..col1-1 of a column-major map of height rows, as lidar.reflectance_map._Accumulator.finish
 * does with numpy: the sums become means (divided in double and rounded to float32, as numpy divides float32 by
 * int32), the intensities are normalised to (v - lo) * scale clipped to [0, 1] when normalise is set, and an empty
 * cell's maximum becomes NaN. Marks the rows that hold a point in row_used (height bytes, only ever set) and the
 * columns in col_used (col1 - col0 bytes). */
TARGETS void bs_finish(int64_t height, int64_t col0, int64_t col1, int32_t normalise, float lo, float scale,
                       const int32_t *count, float *sum_i, float *sum_r, float *max_i, uint8_t *row_used,
                       uint8_t *col_used)
{
    for (int64_t c = col0; c < col1; ++c) {
        uint8_t any = 0;
        const int64_t base = c * height;
        for (int64_t r = 0; r < height; ++r) {
            const int64_t k = base + r;
            const int32_t n = count[k];
            float mean_i = (float)((double)sum_i[k] / (double)n);
            float top = max_i[k];
            if (normalise) {
                mean_i = clip01((mean_i - lo) * scale);
                top = clip01((top - lo) * scale);
            }
            sum_i[k] = mean_i;
            sum_r[k] = (float)((double)sum_r[k] / (double)n);
            max_i[k] = n != 0 ? top : NAN;
            row_used[r] |= (uint8_t)(n != 0);
            any |= (uint8_t)(n != 0);
        }
        col_used[c - col0] = any;
    }
}
