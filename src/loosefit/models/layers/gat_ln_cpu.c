/* One GAT-LN layer's attention and aggregation on the CPU, fused: loosefit's default design (per-node Lipschitz
 * normalisation, neighbourhood-centred scores, concatenated heads; SwinGar Eq. 4 and
 * loosefit/models/layers/gat_ln.py, whose eager passes this computes in one sweep over the vertices).
 *
 * Per batch b and vertex v, over the n valid slots d of its attention table row (t = table[v, d]):
 *   mu      = (1/n) sum_d x[t]                                    the neighbourhood's mean feature
 *   feat    = max_d max(|x[t] - mu|, eps)                         its largest centred feature norm
 *   centre  = u_dst[v] - (1/n) sum_d (u_dst[t] + u_src[t])        c_dst . (x_v - mu) - c_src . mu (the scores are
 *                                                                 linear: c . mu is the mean of c . x_t)
 *   s[d, h] = u_src[t, h] + centre[h]                             c_src . (x_t - mu) + c_dst . (x_v - mu)
 *   scale_h = alpha / max(max(|s[., h]|, eps), feat * lip[h])     the per-node normaliser
 *   P[d, h] = softmax_d(leaky_relu(scale_h s[d, h]))              over the valid slots
 *   out[v, o] = act(bias[o] + sum_d P[d, head_of[o]] y[t, o])     each channel weighted by its head; act: tanh
 *                                                                 (activation 1) or none (0)
 *
 * Arrays are C-contiguous float32 (int64 indices, one byte per validity flag):
 *   x (B, V, C_in); y (B, V, C_out), the projections x W; u (B, V, 2 H), c_dst . x then c_src . x per head;
 *   lip (H); table (V, D); valid (V, D), slot 0 valid; head_of (C_out), non-decreasing (each head's channels one
 *   block, in head order); bias (C_out); out (B, V, C_out).
 * Single-threaded. Returns 0, or -1 where its scratch memory could not be had.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define LANES 16

/* |a - b|^2 over n floats, in LANES partial sums (a reduction the compiler can vectorise without reassociating). */
static float squared_distance(const float *a, const float *b, int64_t n) {
    float acc[LANES] = {0};
    int64_t i = 0;
    for (; i + LANES <= n; i += LANES)
        for (int l = 0; l < LANES; l++) {
            float d = a[i + l] - b[i + l];
            acc[l] += d * d;
        }
    float s = 0.0f;
    for (; i < n; i++) {
        float d = a[i] - b[i];
        s += d * d;
    }
    for (int l = 0; l < LANES; l++) s += acc[l];
    return s;
}

/* e^z for |z| <= 87: z = n ln2 + r with |r| <= ln2 / 2, e^r by its degree-7 Taylor polynomial (relative error below
 * 2e-8 there), 2^n written into the exponent bits. Branch-free, so that the loops around it vectorise. */
static inline float exp_bounded(float z) {
    float n = floorf(z * 1.44269504088896341f + 0.5f);
    float r = z - n * 0.693359375f + n * 2.12194440e-4f;  /* ln2 in two parts: the first exact in float */
    float p = 1.0f / 5040.0f;
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    int32_t bits = ((int32_t)n + 127) << 23;
    float two_n;
    memcpy(&two_n, &bits, sizeof two_n);
    return p * two_n;
}

/* o[k] <- tanh(o[k] + bias[k]) (activation 1) or o[k] + bias[k] (0). tanh(z) = 1 - 2 / (e^(2|z|) + 1) with the sign
 * of z, |z| clamped at 9 (where tanh is 1 to float32's precision): absolute error near 1e-7. */
static void finish(float *restrict o, const float *restrict bias, int activation, int64_t C_out) {
    if (!activation) {
        for (int64_t k = 0; k < C_out; k++) o[k] += bias[k];
        return;
    }
    for (int64_t k = 0; k < C_out; k++) {
        float z = o[k] + bias[k];
        float a = z < 0.0f ? -z : z;
        float e = exp_bounded(2.0f * (a < 9.0f ? a : 9.0f));
        float t = 1.0f - 2.0f / (e + 1.0f);
        o[k] = z < 0.0f ? -t : t;
    }
}

/* sd[h] = u[h] + c[h]; rows[h] += sd[h]^2 */
static void add_scores(float *restrict sd, float *restrict rows, const float *restrict u, const float *restrict c,
                       int64_t H) {
    for (int64_t h = 0; h < H; h++) {
        float z = u[h] + c[h];
        sd[h] = z;
        rows[h] += z * z;
    }
}

/* acc[k] += a[k] (k < n) */
static void add_to(float *restrict acc, const float *restrict a, int64_t n) {
    for (int64_t k = 0; k < n; k++) acc[k] += a[k];
}

/* acc[k] *= f (k < n) */
static void scale_by(float *restrict acc, float f, int64_t n) {
    for (int64_t k = 0; k < n; k++) acc[k] *= f;
}

/* rows[h] <- alpha / max(max(sqrt(rows[h]), eps), feat lip[h]): the row norms become the heads' score scales */
static void score_scales(float *restrict rows, const float *restrict lip, float feat, float alpha, float eps,
                         int64_t H) {
    for (int64_t h = 0; h < H; h++) {
        float r = sqrtf(rows[h]), f = feat * lip[h];
        r = r > eps ? r : eps;
        rows[h] = alpha / (r > f ? r : f);
    }
}

/* sd[h] <- exp(leaky_relu(sd[h] scale[h])); sum[h] += sd[h] */
static void exp_scores(float *restrict sd, float *restrict sum, const float *restrict scale, float slope,
                       int64_t H) {
    for (int64_t h = 0; h < H; h++) {
        float z = sd[h] * scale[h];
        z = z > 0.0f ? z : slope * z;
        z = exp_bounded(z);
        sd[h] = z;
        sum[h] += z;
    }
}

/* o[k] += sd[h] inv[h] y[k] for every channel k of head h, its channels [start[h], start[h + 1]): each channel's
 * weight written out first (w, C_out floats), so that the products run in one loop over all the channels however
 * narrow the heads (SwinGar's 32 heads of 8 channels) */
static void aggregate(float *restrict o, float *restrict w, const float *restrict sd, const float *restrict inv,
                      const int64_t *restrict start, const float *restrict y, int64_t H, int64_t C_out) {
    for (int64_t h = 0; h < H; h++) {
        float p = sd[h] * inv[h];
        for (int64_t k = start[h]; k < start[h + 1]; k++) w[k] = p;
    }
    for (int64_t k = 0; k < C_out; k++) o[k] += w[k] * y[k];
}

int gat_ln_concat_node_centred(int64_t B, int64_t V, int64_t D, int64_t C_in, int64_t C_out, int64_t H,
                               const float *x, const float *y, const float *u, const float *lip, const int64_t *table,
                               const uint8_t *valid, const int64_t *head_of, const float *bias, int activation,
                               float alpha, float slope, float eps, float *out) {
    float *s = malloc(sizeof(float) * (size_t)(D * H + 4 * H + C_in + C_out));
    int64_t *start = malloc(sizeof(int64_t) * (size_t)(H + 1));
    if (!s || !start) {
        free(s);
        free(start);
        return -1;
    }
    float *rows = s + D * H;    /* (H) */
    float *sum = rows + H;      /* (H) */
    float *centre = sum + H;    /* (2 H): the neighbourhood's mean of u, then the centre in its first H */
    float *mu = centre + 2 * H; /* (C_in) */
    float *w = mu + C_in;       /* (C_out): a slot's weight per channel */
    /* each head's channels are one contiguous block, in head order (loosefit.models.layers.gat_ln.head_columns) */
    for (int64_t h = 0, k = 0; h <= H; h++) {
        while (k < C_out && head_of[k] < h) k++;
        start[h] = k;
    }
    for (int64_t b = 0; b < B; b++) {
        const float *xb = x + b * V * C_in, *yb = y + b * V * C_out, *ub = u + b * V * 2 * H;
        float *ob = out + b * V * C_out;
        for (int64_t v = 0; v < V; v++) {
            const int64_t *t = table + v * D;
            const uint8_t *ok = valid + v * D;
            int64_t n = 0;
            memset(mu, 0, sizeof(float) * (size_t)C_in);
            memset(centre, 0, sizeof(float) * (size_t)(2 * H));
            for (int64_t d = 0; d < D; d++) {
                if (!ok[d]) continue;
                n++;
                add_to(mu, xb + t[d] * C_in, C_in);
                add_to(centre, ub + t[d] * 2 * H, 2 * H);
            }
            scale_by(mu, 1.0f / (float)n, C_in);
            for (int64_t h = 0; h < H; h++) centre[h] = ub[v * 2 * H + h] - (centre[h] + centre[H + h]) / (float)n;
            float feat = eps;
            for (int64_t d = 0; d < D; d++) {
                if (!ok[d]) continue;
                float f = sqrtf(squared_distance(xb + t[d] * C_in, mu, C_in));
                if (f > feat) feat = f;
            }
            memset(rows, 0, sizeof(float) * (size_t)(2 * H)); /* rows and sum */
            for (int64_t d = 0; d < D; d++)
                if (ok[d]) add_scores(s + d * H, rows, ub + t[d] * 2 * H + H, centre, H);
            score_scales(rows, lip, feat, alpha, eps, H);
            for (int64_t d = 0; d < D; d++)
                if (ok[d]) exp_scores(s + d * H, sum, rows, slope, H);
            for (int64_t h = 0; h < H; h++) sum[h] = 1.0f / sum[h];
            float *o = ob + v * C_out;
            memset(o, 0, sizeof(float) * (size_t)C_out);
            for (int64_t d = 0; d < D; d++)
                if (ok[d]) aggregate(o, w, s + d * H, sum, start, yb + t[d] * C_out, H, C_out);
            finish(o, bias, activation, C_out);
        }
    }
    free(s);
    free(start);
    return 0;
}
