/* The pose stage of tactile_manip.perception.pose in one pass of C over a float32 depth image.
 *
 * tm_contact_moments() computes what pose.py's numpy path (_kept_contact, _weights, _in_aperture,
 * _second_moments) computes, for a finite float32 image whose background has been removed already:
 *   1. the contact: pixels with depth > threshold, labelled as 4-connected runs of pixels per row (a run joins
 *      the runs of the row above that share a column with it, through a union-find over runs); regions smaller
 *      than min_fraction of the largest are removed;
 *   2. the filter: max(depth, 0) with the removed regions zeroed, Gaussian-filtered (the kernel given, zero
 *      beyond the image) over the kept contact's box plus the kernel's radius: a vertical then a horizontal
 *      pass over the box plus twice the radius (all the input the output sees);
 *   3. the weights max(filtered - threshold, 0), counted, and their moments in double: the centroid over all
 *      of them, the central second moments over them times the aperture (when given, and unless the box lies
 *      inside it or fewer than min_px weighted pixels are left in it).
 * Arithmetic is float32 up to the weights (as the numpy path's BLAS products) and double in the moments, so
 * the two paths agree to float32 rounding (tests/perception/test_pose_fast.py checks both against the float64
 * reference). Plain C99 without Python.h: pose_kernel.py loads it with ctypes, so it builds where Python's
 * headers are missing; setup.py builds it as an optional extension (the numpy path runs when it is absent).
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#include <features.h>
#if defined(__GLIBC__)
/* one build for every x86-64 machine: the loader picks the AVX2/FMA clone where the CPU has it */
#define TM_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#endif
#endif
#ifndef TM_CLONES
#define TM_CLONES
#endif
#if defined(_MSC_VER)
#define TM_EXPORT __declspec(dllexport)  /* ctypes finds only exported symbols in a DLL */
#ifndef restrict
#define restrict __restrict
#endif
#else
#define TM_EXPORT
#endif

enum { TM_OK = 0, TM_EMPTY = 1, TM_TOO_SMALL = 2, TM_NO_MEMORY = -1, TM_BAD_ARGUMENT = -2 };

/* out[] slots, mirrored in pose_kernel.py */
enum { O_RAW_PX, O_N_PX, O_CX, O_CY, O_SXX, O_SYY, O_SXY, O_SIZE };

typedef struct { int row, c0, c1; } run_t;

#if defined(_MSC_VER)
#define TM_THREAD_LOCAL __declspec(thread)
#else
#define TM_THREAD_LOCAL _Thread_local
#endif

/* Scratch buffers kept from call to call, one set per thread (the kernel holds no lock): allocating them on
   every call cost more than the work on a small contact (large blocks are fresh pages to fault in). */
enum { B_RUNS, B_PARENT, B_SIZE, B_MASK, B_SPANS, B_CROP, B_VERTICAL, B_WEIGHTS, B_X, B_COUNTS, B_COLUMNS,
       B_COUNT };
static TM_THREAD_LOCAL void *scratch[B_COUNT];
static TM_THREAD_LOCAL size_t scratch_bytes[B_COUNT];

/* Buffer ``which`` with room for ``bytes`` at least (its old contents are not kept); NULL when out of memory. */
static void *buffer(int which, size_t bytes) {
    if (bytes > scratch_bytes[which]) {
        free(scratch[which]);
        scratch[which] = malloc(bytes);
        scratch_bytes[which] = scratch[which] ? bytes : 0;
    }
    return scratch[which];
}  /* pixels [c0, c1) of a row above the threshold */

static int find_root(int *parent, int i) {
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

/* The runs of pixels above the threshold, row by row; returns their number. ``mask``: w + 8 bytes of scratch.
 * Each row is compared into bytes first (a loop that vectorises), then scanned eight bytes at a time through
 * the runs' insides and the gaps between them. */
static int find_runs(const float *d, int h, int w, float threshold, run_t *runs, unsigned char *mask) {
    const uint64_t zeros = 0, ones = 0x0101010101010101ULL;
    int n = 0;
    memset(mask + w, 0, 8);  /* a gap after the row's end stops every scan */
    for (int r = 0; r < h; ++r) {
        const float *row = d + (size_t)r * w;
        for (int c = 0; c < w; ++c) mask[c] = row[c] > threshold;
        int c = 0;
        while (c < w) {
            uint64_t word;
            memcpy(&word, mask + c, 8);
            if (word == zeros) { c += 8; continue; }
            if (!mask[c]) { ++c; continue; }
            const int start = c;
            for (memcpy(&word, mask + c, 8); word == ones; memcpy(&word, mask + c, 8)) c += 8;
            while (mask[c]) ++c;
            runs[n].row = r;
            runs[n].c0 = start;
            runs[n].c1 = c;
            ++n;
        }
    }
    return n;
}

/* Union of every run with the runs of the row above that share a column with it (4-connectivity). */
static void join_runs(const run_t *runs, int n, int *parent) {
    for (int i = 0; i < n; ++i) parent[i] = i;
    int above = 0;  /* first run of the row above the current run's row */
    for (int i = 0; i < n; ++i) {
        while (above < i && runs[above].row < runs[i].row - 1) ++above;
        for (int j = above; j < i && runs[j].row == runs[i].row - 1; ++j) {
            if (runs[j].c0 < runs[i].c1 && runs[i].c0 < runs[j].c1) {
                int a = find_root(parent, i), b = find_root(parent, j);
                if (a != b) parent[a < b ? b : a] = a < b ? a : b;
            }
        }
    }
}

#define TM_BLOCK 32  /* output pixels per register block: four AVX vectors of accumulators */

/* dst[k] = sum_j kernel[j] * src[k + j * step] for k < n: one output row of a pass, in register blocks. */
TM_CLONES
static void filter_line(const float *restrict src, ptrdiff_t step, float *restrict dst, int n,
                        const float *restrict kernel, int taps) {
    int k = 0;
    for (; k + TM_BLOCK <= n; k += TM_BLOCK) {
        float acc[TM_BLOCK];
        for (int i = 0; i < TM_BLOCK; ++i) acc[i] = 0.0f;
        for (int j = 0; j < taps; ++j) {
            const float g = kernel[j], *s = src + k + j * step;
            for (int i = 0; i < TM_BLOCK; ++i) acc[i] += g * s[i];
        }
        for (int i = 0; i < TM_BLOCK; ++i) dst[k + i] = acc[i];
    }
    for (; k + 8 <= n; k += 8) {  /* the rest in vectors of 8, then one by one */
        float acc[8];
        for (int i = 0; i < 8; ++i) acc[i] = 0.0f;
        for (int j = 0; j < taps; ++j) {
            const float g = kernel[j], *s = src + k + j * step;
            for (int i = 0; i < 8; ++i) acc[i] += g * s[i];
        }
        for (int i = 0; i < 8; ++i) dst[k + i] = acc[i];
    }
    for (; k < n; ++k) {
        float acc = 0.0f;
        for (int j = 0; j < taps; ++j) acc += kernel[j] * src[k + j * step];
        dst[k] = acc;
    }
}

/* Adds one row (at height y) of the weights max(v - threshold, 0), times the aperture row a when a is not NULL,
 * to the column sums: count[k] (weights > 0), sum w, sum w y, sum w y^2 (no reduction across k: it vectorizes). */
TM_CLONES
static void add_row(const float *restrict v, const float *restrict a, int n, float threshold, double y,
                    double *restrict count, double *restrict s0, double *restrict sy, double *restrict syy) {
    /* written without branches (a select on the sign as a product with 0 or 1) so that it vectorizes */
    if (a) {
        for (int k = 0; k < n; ++k) {
            const float above = v[k] - threshold, wk = above * (float)(above > 0.0f) * a[k];
            const double wy = (double)wk * y;
            count[k] += (double)(wk > 0.0f);
            s0[k] += wk; sy[k] += wy; syy[k] += wy * y;
        }
    } else {
        for (int k = 0; k < n; ++k) {
            const float above = v[k] - threshold, positive = (float)(above > 0.0f), wk = above * positive;
            const double wy = (double)wk * y;
            count[k] += positive;
            s0[k] += wk; sy[k] += wy; syy[k] += wy * y;
        }
    }
}

/* The moments' sums from the column sums: count, sum w, sum w x, sum w x^2, sum w y, sum w y^2, sum w x y. */
static void reduce_columns(const double *count, const double *s0, const double *sy, const double *syy,
                           const double *x, int n, double *m) {
    double c = 0.0, m1 = 0.0, mx = 0.0, mxx = 0.0, my = 0.0, myy = 0.0, mxy = 0.0;
    for (int k = 0; k < n; ++k) {
        c += count[k];
        m1 += s0[k]; mx += s0[k] * x[k]; mxx += s0[k] * x[k] * x[k];
        my += sy[k]; myy += syy[k]; mxy += sy[k] * x[k];
    }
    m[0] = c; m[1] = m1; m[2] = mx; m[3] = mxx; m[4] = my; m[5] = myy; m[6] = mxy;
}

/* The contact's moments in the image d (h, w), row-major float32 with no NaN or infinity.
 *   kernel (taps = 2 radius + 1): the float32 Gaussian kernel; taps = 1 with kernel {1}: no filter.
 *   disc (h, w) float32 or NULL: the moments' aperture; min_px: the fewest weighted pixels for a defined angle
 *   (and for the aperture to apply).
 * out (O_SIZE doubles): the kept contact's pixel count (raw), the weights' count, the centroid (cx, cy)
 * of all weights, the central second moments (sxx, syy, sxy) of the windowed or all weights, mm.
 * Returns TM_OK, TM_EMPTY (no pixel above the threshold), TM_TOO_SMALL (fewer than min_px weights: only the
 * counts are set), TM_NO_MEMORY or TM_BAD_ARGUMENT. */
TM_EXPORT int tm_contact_moments(const float *d, int h, int w, float threshold, double min_fraction,
                                 const float *kernel, int taps, const float *disc, int min_px, double pixel_mm,
                                 double *out) {
    if (h <= 0 || w <= 0 || taps < 1 || taps % 2 == 0 || !(pixel_mm > 0.0)) return TM_BAD_ARGUMENT;
    for (int i = 0; i < O_SIZE; ++i) out[i] = 0.0;
    const int radius = taps / 2;
    size_t max_runs = (size_t)h * (size_t)((w + 1) / 2);
    run_t *runs = buffer(B_RUNS, max_runs * sizeof *runs);
    int *parent = buffer(B_PARENT, max_runs * sizeof *parent);
    long long *size = buffer(B_SIZE, max_runs * sizeof *size);
    unsigned char *mask = buffer(B_MASK, (size_t)w + 8);
    int *spans = buffer(B_SPANS, 4 * (size_t)h * sizeof *spans);  /* per row: kept columns, then needed ones */
    if (!runs || !parent || !size || !mask || !spans) return TM_NO_MEMORY;

    int n = find_runs(d, h, w, threshold, runs, mask);
    if (n == 0) return TM_EMPTY;
    join_runs(runs, n, parent);
    long long largest = 0;
    for (int i = 0; i < n; ++i) size[i] = 0;
    for (int i = 0; i < n; ++i) {
        int root = find_root(parent, i);
        parent[i] = root;
        size[root] += runs[i].c1 - runs[i].c0;
    }
    for (int i = 0; i < n; ++i) if (parent[i] == i && size[i] > largest) largest = size[i];
    const double keep_from = min_fraction * (double)largest;
    int r0 = h, r1 = 0, c0 = w, c1 = 0, removed = 0;
    long long raw_px = 0;
    int *kept_lo = spans, *kept_hi = spans + h;  /* each row's kept contact spans columns [lo, hi) (lo >= hi: none) */
    for (int r = 0; r < h; ++r) { kept_lo[r] = w; kept_hi[r] = 0; }
    for (int i = 0; i < n; ++i) {
        if ((double)size[parent[i]] >= keep_from) {
            if (runs[i].c0 < kept_lo[runs[i].row]) kept_lo[runs[i].row] = runs[i].c0;
            if (runs[i].c1 > kept_hi[runs[i].row]) kept_hi[runs[i].row] = runs[i].c1;
            raw_px += runs[i].c1 - runs[i].c0;
            if (runs[i].row < r0) r0 = runs[i].row;
            if (runs[i].row + 1 > r1) r1 = runs[i].row + 1;
            if (runs[i].c0 < c0) c0 = runs[i].c0;
            if (runs[i].c1 > c1) c1 = runs[i].c1;
        } else {
            removed = 1;
        }
    }
    out[O_RAW_PX] = (double)raw_px;

    /* the input the filter reads: the kept box plus twice the radius, zero-padded by the radius on every side
       (beyond the image: zero) so both passes run without bounds checks */
    const int reach = 2 * radius;
    const int e0 = r0 - reach > 0 ? r0 - reach : 0, e1 = r1 + reach < h ? r1 + reach : h;
    const int f0 = c0 - reach > 0 ? c0 - reach : 0, f1 = c1 + reach < w ? c1 + reach : w;
    const int o0 = r0 - radius > 0 ? r0 - radius : 0, o1 = r1 + radius < h ? r1 + radius : h;
    const int p0 = c0 - radius > 0 ? c0 - radius : 0, p1 = c1 + radius < w ? c1 + radius : w;
    const int ch = (e1 - e0) + 2 * radius, cw = (f1 - f0) + 2 * radius;  /* crop rows and columns, padded */
    const int oh = o1 - o0, ow = p1 - p0;
    float *crop = buffer(B_CROP, (size_t)ch * cw * sizeof *crop);
    float *vertical = buffer(B_VERTICAL, (size_t)oh * cw * sizeof *vertical);
    float *weights = buffer(B_WEIGHTS, (size_t)oh * ow * sizeof *weights);
    double *x = buffer(B_X, (size_t)ow * sizeof *x);
    if (!crop || !vertical || !weights || !x) return TM_NO_MEMORY;
    memset(crop, 0, (size_t)radius * cw * sizeof *crop);  /* the padding: rows above and below, columns beside */
    memset(crop + (size_t)(ch - radius) * cw, 0, (size_t)radius * cw * sizeof *crop);
    for (int r = e0; r < e1; ++r) {
        const float *src = d + (size_t)r * w;
        float *row = crop + (size_t)(r - e0 + radius) * cw, *dst = row + radius - f0;
        for (int c = 0; c < radius; ++c) row[c] = row[cw - 1 - c] = 0.0f;
        for (int c = f0; c < f1; ++c) dst[c] = src[c] > 0.0f ? src[c] : 0.0f;
    }
    if (removed) {
        for (int i = 0; i < n; ++i) {
            if ((double)size[parent[i]] >= keep_from || runs[i].row < e0 || runs[i].row >= e1) continue;
            int a = runs[i].c0 > f0 ? runs[i].c0 : f0, b = runs[i].c1 < f1 ? runs[i].c1 : f1;
            float *dst = crop + (size_t)(runs[i].row - e0 + radius) * cw + radius - f0;
            for (int c = a; c < b; ++c) dst[c] = 0.0f;
        }
    }
    /* Only the pixels within the radius of the kept contact can weigh (elsewhere the filter reads depths at or
       below the threshold only): output row o needs columns [lo, hi), the kept columns of the rows within the
       radius, widened by the radius; the vertical pass there needs the radius more on each side. */
    int *need_lo = spans + 2 * h, *need_hi = spans + 3 * h;
    for (int o = 0; o < oh; ++o) {
        int lo = w, hi = 0;
        const int first = o0 + o - radius > r0 ? o0 + o - radius : r0;
        const int last = o0 + o + radius < r1 - 1 ? o0 + o + radius : r1 - 1;
        for (int r = first; r <= last; ++r) {
            if (kept_lo[r] < lo) lo = kept_lo[r];
            if (kept_hi[r] > hi) hi = kept_hi[r];
        }
        need_lo[o] = lo - radius > p0 ? lo - radius : p0;
        need_hi[o] = hi + radius < p1 ? hi + radius : p1;
    }
    for (int o = 0; o < oh; ++o) {
        const int lo = need_lo[o], hi = need_hi[o];
        if (lo >= hi) continue;
        /* output pixel (o0 + o, c) reads padded crop rows from (o0 + o - radius) - e0 + radius and, in the
           vertical pass's output, padded columns from (c - radius) - f0 + radius */
        float *v = vertical + (size_t)o * cw + (lo - f0);
        filter_line(crop + (size_t)(o0 - e0 + o) * cw + (lo - f0), cw, v, hi - lo + 2 * radius, kernel, taps);
        filter_line(v, 1, weights + (size_t)o * ow + (lo - p0), hi - lo, kernel, taps);
    }

    for (int q = 0; q < ow; ++q) x[q] = (p0 + q - (w - 1) / 2.0) * pixel_mm;
    int window = 0;
    if (disc) {  /* a box whose corners are inside the (convex) aperture is inside it */
        const float corners[4] = {disc[(size_t)o0 * w + p0], disc[(size_t)o0 * w + p1 - 1],
                                  disc[(size_t)(o1 - 1) * w + p0], disc[(size_t)(o1 - 1) * w + p1 - 1]};
        window = !(corners[0] == 1.0f && corners[1] == 1.0f && corners[2] == 1.0f && corners[3] == 1.0f);
    }
    /* column sums per weights used (0: all, 1: windowed): count, sum w, sum w y, sum w y^2 */
    double *count = buffer(B_COUNTS, 2 * (size_t)ow * sizeof *count);
    double *cols = buffer(B_COLUMNS, 6 * (size_t)ow * sizeof *cols);
    if (!count || !cols) return TM_NO_MEMORY;
    memset(count, 0, 2 * (size_t)ow * sizeof *count);
    memset(cols, 0, 6 * (size_t)ow * sizeof *cols);
    for (int o = 0; o < oh; ++o) {
        const int lo = need_lo[o] - p0, n_cols = need_hi[o] - need_lo[o];
        if (n_cols <= 0) continue;
        const double y = -(o0 + o - (h - 1) / 2.0) * pixel_mm;
        const float *v = weights + (size_t)o * ow + lo;
        add_row(v, NULL, n_cols, threshold, y, count + lo, cols + lo, cols + ow + lo, cols + 2 * ow + lo);
        if (window) add_row(v, disc + (size_t)(o0 + o) * w + p0 + lo, n_cols, threshold, y, count + ow + lo,
                            cols + 3 * ow + lo, cols + 4 * ow + lo, cols + 5 * ow + lo);
    }
    /* per weights used: count, sum w, sum w x, sum w x^2, sum w y, sum w y^2, sum w x y */
    double m[2][7];
    reduce_columns(count, cols, cols + ow, cols + 2 * ow, x, ow, m[0]);
    reduce_columns(count + ow, cols + 3 * ow, cols + 4 * ow, cols + 5 * ow, x, ow, m[1]);
    out[O_N_PX] = m[0][0];
    if (m[0][0] < min_px) return TM_TOO_SMALL;
    out[O_CX] = m[0][2] / m[0][1];
    out[O_CY] = m[0][4] / m[0][1];
    const double *s = window && m[1][0] >= min_px ? m[1] : m[0];  /* the aperture's, when it holds enough */
    const double cx = s[2] / s[1], cy = s[4] / s[1];
    out[O_SXX] = s[3] / s[1] - cx * cx;
    out[O_SYY] = s[5] / s[1] - cy * cy;
    out[O_SXY] = s[6] / s[1] - cx * cy;

    return TM_OK;
}

/* setuptools builds this file as an extension module; it is loaded with ctypes, never imported. */
TM_EXPORT void *PyInit__pose_kernel(void) { return 0; }
