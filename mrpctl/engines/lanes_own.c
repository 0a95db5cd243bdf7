/* mrpctl: the W-lane driver of an engine whose lanes have their own streams (appended after lanes_driver.c).
 *
 * mrpctl.engines.lanes appends this file, and puts noise.c (the one generator of the package's streams) in front
 * of the emitted code, only for a lane engine with own_streams: the other engines' libraries are lanes_driver.c's
 * alone. Besides lanes_driver.c's roles, an input of role MRPCTL_ROLE_NOISE is each lane's noise row of the sample,
 * drawn here.
 */
/* samples of noise drawn at a time per lane (as the scalar driver's block) */
#define MRPCTL_NOISE_BLOCK 64

/* The noise rows of samples k .. k + count - 1 of every lane into block[(r * 6 + j) * W + l] (row r, number j, lane
 * l): number 3 s + c of row r is scale_s n_s(3 (k + r) + c) of lane l's stream s (0 attitude, 1 rate), the value of
 * mrpctl_normal_rows for that lane (scale > 0: the ziggurat's accepted first attempt times the signed scale, a
 * rejected one scale times mrpctl_stream_normal_slow; else exact zeros). With AVX-512 (F and DQ) the first attempt
 * is computed 8 lanes at a time (below); else lane by lane in mrpctl_normal_rows' loop. */
#if defined(__AVX512F__) && defined(__AVX512DQ__) && MRPCTL_W % 8 == 0
#include <immintrin.h>

/* A lower bound on the first attempt's acceptance, per group of 8 layers (i >> 3): the uniform's integer
 * m = h >> 11 < mrpctl_zig_sure[i >> 3] (an integer below 2^53, exact in a double) implies x = m X[i] 2^-53 < X[i + 1]
 * (as the ziggurat computes x: one rounded product, monotone in m) for every layer i of the group except 255 (whose
 * X[256] = 0 accepts nothing). Each entry is the least, over its layers, of the least m with m X[i] 2^-53 >= X[i + 1]
 * (bisection in float64 on the tables above; tests/test_lane_noise.py checks every entry against the tables). About
 * 2 % of the numbers are below no bound: they are decided exactly afterwards, with mrpctl_stream_normal_slow for the
 * rejected ones. */
static const double mrpctl_zig_sure[32] __attribute__((aligned(64))) = {
    0x1.de67b004bdec9p+52, 0x1.f86565e3c45dap+52, 0x1.fb30bc36574e9p+52, 0x1.fc4000732aaadp+52,
    0x1.fccfb416d57b1p+52, 0x1.fd27e8e3a8e51p+52, 0x1.fd62760165a95p+52, 0x1.fd8afea1e63fbp+52,
    0x1.fda7883bd4844p+52, 0x1.fdbb7c84408fap+52, 0x1.fdc8e94000d9dp+52, 0x1.fdd115c6d38f3p+52,
    0x1.fdd4cd1f85ae1p+52, 0x1.fdd14c16cc686p+52, 0x1.fdca24e3b610dp+52, 0x1.fdbf43c1fa828p+52,
    0x1.fdb06afc95303p+52, 0x1.fd9d2e9119166p+52, 0x1.fd84ea562b428p+52, 0x1.fd66b0bfc5496p+52,
    0x1.fd412e757ccf6p+52, 0x1.fd127b90810c9p+52, 0x1.fcd7ccc3c2355p+52, 0x1.fc8ce8da8ee69p+52,
    0x1.fc2b278517098p+52, 0x1.fba770230e53ap+52, 0x1.faedd5391d063p+52, 0x1.f9d6a9b1fd933p+52,
    0x1.f8060c1fed8afp+52, 0x1.f46c1eb03f4e3p+52, 0x1.e9e8d2ac24ab0p+52, 0x1.8117d31f78cc2p+52
};

/* Mix13 of 8 lanes (vpmullq: the same 64-bit products as the scalar's). */
static inline __m512i mrpctl_mix13_x8(__m512i z) {
  z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 30)),
                         _mm512_set1_epi64((long long)UINT64_C(0xBF58476D1CE4E5B9)));
  z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 27)),
                         _mm512_set1_epi64((long long)UINT64_C(0x94D049BB133111EB)));
  return _mm512_xor_si512(z, _mm512_srli_epi64(z, 31));
}

/* Positions listed at most (then decided): a fixed size (about 60 of a block's 64 x 6 x 8 numbers are listed). */
#define MRPCTL_ODD 512

/* The listed positions of the block (see mrpctl_lane_noise) decided exactly, as mrpctl_normal_rows does: accepted
 * by the first attempt (x < X[i + 1]) as the signed scale times x, else scale times mrpctl_stream_normal_slow. */
static void mrpctl_lane_noise_odd(const unsigned long long* keys, const double* sigmas, long long k, double* block,
                                  const long long* odd, long long n_odd) {
  long long f;
  for (f = 0; f < n_odd; ++f) {
    const long long at = odd[f], l = at % MRPCTL_W, row = at / MRPCTL_W, j = row % 6, s = j / 3;
    const uint64_t key = (uint64_t)keys[s * MRPCTL_W + l], n = (uint64_t)(3 * (k + row / 6) + j % 3);
    const double scale = sigmas[s * MRPCTL_W + l];
    const uint64_t h = mrpctl_stream_value(key, n << 12);
    const int i = (int)(h & 255u);
    const double x = (double)(int64_t)(h >> 11) * mrpctl_zig_xs[i];
    block[at] = x < mrpctl_zig_x[i + 1] ? mrpctl_signed(scale * x, h) : scale * mrpctl_stream_normal_slow(key, n);
  }
}

/* mrpctl_lane_noise 8 lanes at a time: per number, the 8 lanes' values h (counter z = key + ((n << 12) + 1) C,
 * C = 0x9E3779B97F4A7C15, as mrpctl_stream_value), x = (h >> 11) X[i] 2^-53 (the conversion is exact: < 2^53; one
 * gather of the table), the sign of bit 8 as a sign-bit flip of scale x (= (-scale) x bit for bit: the scales are
 * finite, the sensors' validated 1 sigma, so scale x is never a NaN), zeros where
 * !(scale > 0). A lane whose number is not surely accepted (mrpctl_zig_sure) has its position appended (branch free) to
 * a list of at most MRPCTL_ODD, decided exactly (mrpctl_lane_noise_odd) when it is nearly full and after the block, so
 * every number is mrpctl_normal_rows'. */
static void mrpctl_lane_noise(const unsigned long long* keys, const double* sigmas, long long k, long long count,
                              double* block) {
  const uint64_t step = UINT64_C(0x9E3779B97F4A7C15) << 12;
  const uint64_t first = (((uint64_t)(3 * k) << 12) + 1u) * UINT64_C(0x9E3779B97F4A7C15);
  const __m512i layer_mask = _mm512_set1_epi64(255), sign = _mm512_set1_epi64((long long)(UINT64_C(1) << 63));
  const __m512i upper_half = _mm512_set1_epi64(16), iota = _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0);
  const __m512d sure0 = _mm512_load_pd(mrpctl_zig_sure), sure1 = _mm512_load_pd(mrpctl_zig_sure + 8);
  const __m512d sure2 = _mm512_load_pd(mrpctl_zig_sure + 16), sure3 = _mm512_load_pd(mrpctl_zig_sure + 24);
  long long odd[MRPCTL_ODD + 8]; /* + 8: room for a full 8-lane store */
  long long n_odd = 0;
  int g;
  for (g = 0; g < MRPCTL_W; g += 8) {
    __m512i key[2];
    __m512d scale[2];
    __mmask8 keep[2];
    uint64_t offset = first;
    long long r;
    int s, c;
    for (s = 0; s < 2; ++s) {
      key[s] = _mm512_loadu_si512((const void*)(keys + s * MRPCTL_W + g));
      scale[s] = _mm512_loadu_pd(sigmas + s * MRPCTL_W + g);
      keep[s] = _mm512_cmp_pd_mask(scale[s], _mm512_setzero_pd(), _CMP_GT_OQ);
    }
    for (r = 0; r < count; ++r) {
      if (n_odd > MRPCTL_ODD - 6 * 8) { /* room for a row's 6 x 8 */
        mrpctl_lane_noise_odd(keys, sigmas, k, block, odd, n_odd);
        n_odd = 0;
      }
      for (c = 0; c < 3; ++c, offset += step)
        for (s = 0; s < 2; ++s) {
          const long long at = (r * 6 + 3 * s + c) * MRPCTL_W + g;
          const __m512i h = mrpctl_mix13_x8(_mm512_add_epi64(key[s], _mm512_set1_epi64((long long)offset)));
          const __m512i layer = _mm512_and_si512(h, layer_mask), group = _mm512_srli_epi64(layer, 3);
          const __m512d m = _mm512_cvtepi64_pd(_mm512_srli_epi64(h, 11));
          const __m512d x = _mm512_mul_pd(m, _mm512_i64gather_pd(layer, mrpctl_zig_xs, 8));
          const __m512d sure = _mm512_mask_blend_pd(_mm512_test_epi64_mask(group, upper_half),
                                                    _mm512_permutex2var_pd(sure0, group, sure1),
                                                    _mm512_permutex2var_pd(sure2, group, sure3));
          const __mmask8 unsure =
              keep[s] & (__mmask8)~(_mm512_cmp_pd_mask(m, sure, _CMP_LT_OQ) & _mm512_cmpneq_epi64_mask(layer, layer_mask));
          /* scale x with its sign flipped by bit 8 of h: a ^ (b & c), b = h << 55, c = the sign bit */
          const __m512i bits = _mm512_ternarylogic_epi64(_mm512_castpd_si512(_mm512_mul_pd(scale[s], x)),
                                                         _mm512_slli_epi64(h, 55), sign, 0x78);
          _mm512_storeu_pd(block + at, _mm512_castsi512_pd(_mm512_maskz_mov_epi64(keep[s], bits)));
          _mm512_storeu_si512((void*)(odd + n_odd),
                              _mm512_maskz_compress_epi64(unsure, _mm512_add_epi64(iota, _mm512_set1_epi64(at))));
          n_odd += __builtin_popcount((unsigned)unsure);
        }
    }
  }
  mrpctl_lane_noise_odd(keys, sigmas, k, block, odd, n_odd);
}
#else
static void mrpctl_lane_noise(const unsigned long long* keys, const double* sigmas, long long k, long long count,
                              double* block) {
  const uint64_t step = UINT64_C(0x9E3779B97F4A7C15) << 12;
  int s, l, c;
  for (s = 0; s < 2; ++s)
    for (l = 0; l < MRPCTL_W; ++l) { /* mrpctl_normal_rows' loop for lane l's stream s, its numbers W apart */
      const uint64_t key = (uint64_t)keys[s * MRPCTL_W + l];
      const double scale = sigmas[s * MRPCTL_W + l];
      const double signed_scale[2] = {scale, -scale};
      uint64_t n = (uint64_t)(3 * k);
      uint64_t z = key + ((n << 12) + 1u) * UINT64_C(0x9E3779B97F4A7C15);
      double* out = block + 3 * s * MRPCTL_W + l;
      long long r;
      if (!(scale > 0.0)) {
        for (r = 0; r < count; ++r, out += 6 * MRPCTL_W) out[0] = out[MRPCTL_W] = out[2 * MRPCTL_W] = 0.0;
        continue;
      }
      for (r = 0; r < count; ++r, out += 6 * MRPCTL_W)
        for (c = 0; c < 3; ++c, ++n, z += step) {
          const uint64_t h = mrpctl_mix13(z);
          const int i = (int)(h & 255u);
          const double x = (double)(int64_t)(h >> 11) * mrpctl_zig_xs[i];
          if (__builtin_expect(x < mrpctl_zig_x[i + 1], 1)) out[c * MRPCTL_W] = signed_scale[(h >> 8) & 1u] * x;
          else out[c * MRPCTL_W] = scale * mrpctl_stream_normal_slow(key, n);
        }
    }
}
#endif

/* The newest arrived measurement j*(k + r) of every lane l for r < count into chosen[r * W + l], advancing each lane's
 * arrival ring (latest, slot of k = `slot`) and j* (newest) as the per-sample loop of mrpctl_lanes_run_own did: the
 * jitter does not depend on the run's state, so a block of samples is scheduled at once, lane by lane (first the
 * lane's delays, mrpctl_stream_integer's numbers, in a loop of their own, then its ring in order). */
static void mrpctl_lane_schedule(const long long* keys, const long long* d_min, long long* newest, long long* latest,
                                 long long d, long long k, long long count, long long slot, long long* chosen) {
  long long delays[MRPCTL_NOISE_BLOCK];
  long long r;
  int l;
  for (l = 0; l < MRPCTL_W; ++l) {
    const uint64_t key = (uint64_t)keys[l], span = (uint64_t)(d - d_min[l] + 1);
    long long j = newest[l], at = slot;
    for (r = 0; r < count; ++r) { /* mrpctl_stream_integer(key, k + r, d_min, d) - d_min */
      const uint64_t h = mrpctl_mix13(key + ((((uint64_t)(k + r)) << 12) + 1u) * UINT64_C(0x9E3779B97F4A7C15));
      delays[r] = (long long)(((h >> 32) * span) >> 32);
    }
    for (r = 0; r < count; ++r) {
      long long* entry = latest + at * MRPCTL_W + l;
      long long arrival = at + d_min[l] + delays[r];
      if (arrival > d) arrival -= d + 1;
      if (*entry > j) j = *entry;
      if (k + r - d > j) j = k + r - d; /* the history sample k + r - d arrives at k + r */
      chosen[r * MRPCTL_W + l] = j;
      *entry = LLONG_MIN;
      latest[arrival * MRPCTL_W + l] = k + r; /* every measurement registered before is older than k + r */
      if (++at > d) at = 0;
    }
    newest[l] = j;
  }
}

/* As mrpctl_lanes_run, each lane with its own sensor noise and its own jitter, drawn and scheduled here as the
 * scalar driver (mrpctl/engines/scalar_driver.c) does for its one run, with the generator of noise.c (included in
 * front of this file by mrpctl.engines.lanes for an engine with own streams).
 * noise_keys: null (no noise input), or 2 W stream keys, lane l's attitude key at [l] and its rate key at [W + l];
 * sigmas: the 2 W scales (1 sigma) in the same order (0: exact zeros). The noise input (MRPCTL_ROLE_NOISE) of
 * sample k is row k of (sigma_a n_a(3k + c), sigma_r n_r(3k + c)), c = 0, 1, 2, for each lane (nonzero j of
 * lane l at j W + l), drawn MRPCTL_NOISE_BLOCK samples at a time by mrpctl_lane_noise: the numbers of
 * mrpctl.flight.SensorModel.noise_rows of the lane's sensor (mrpctl_normal_rows').
 * jitter: null (the constant delay d, or `used`), or in-out (3 + d + 1) W values: the lanes' key bits, d_min and
 * j*(k0 - 1), then the arrival ring latest[(d + 1) x W]; measurement j of lane l arrives at j + d_j with d_j =
 * integer(key_l, j) in [d_min_l, d], and j*(k) = max(j*(k - 1), latest[k mod (d + 1)], min(k - d, -1)) (a lane
 * with d_min = d has the constant delay d). The pending measurements j in [k0 - d, k0) are registered again at the
 * start of a slice, so only j*(k0 - 1) is carried. used: null, or (when jitter is null: a given delay
 * sequence per lane) the newest arrived measurement j*(k) of lane l at used[(k - k0) W + l]. */
__attribute__((visibility("default"))) int mrpctl_lanes_run_own(double* carried, const double* constants,
                                                                const double* history, long long k0, long long k1,
                                                                long long d, double* ring, const double* stream,
                                                                long long stream_stride, const long long* used,
                                                                const unsigned long long* noise_keys,
                                                                const double* sigmas, long long* jitter) {
  static double* const unused = 0;
  double buffers[2][MRPCTL_BLOCK] __attribute__((aligned(64)));
  double gathered[MRPCTL_COLUMN] __attribute__((aligned(64)));
  double noise_block[MRPCTL_NOISE_BLOCK * 6 * MRPCTL_W] __attribute__((aligned(64)));
  const double* arg[MRPCTL_N_IN];
  double* res[MRPCTL_N_OUT];
  long long k, slot = k0 % (d + 1), delayed_slot = k0 >= d ? (k0 - d) % (d + 1) : 0;
  long long noise_k0 = k0, noise_k1 = k0, schedule_k0 = k0, schedule_k1 = k0;
  long long schedule[MRPCTL_NOISE_BLOCK * MRPCTL_W];
  long long *keys = 0, *d_min = 0, *newest = 0, *latest = 0;
  int i, l, m, now_index = 0;
  memcpy(buffers[0], carried, sizeof(buffers[0]));
  for (i = 0; i < MRPCTL_N_IN; ++i) arg[i] = constants + mrpctl_in_offset[i] * MRPCTL_W;
  for (i = 0; i < MRPCTL_N_OUT; ++i) res[i] = unused;
  if (jitter) {
    keys = jitter;
    d_min = jitter + MRPCTL_W;
    newest = jitter + 2 * MRPCTL_W;
    latest = jitter + 3 * MRPCTL_W;
    for (i = 0; i < (d + 1) * MRPCTL_W; ++i) latest[i] = LLONG_MIN;
    for (l = 0; l < MRPCTL_W; ++l)
      for (k = k0 - d > 0 ? k0 - d : 0; k < k0; ++k) {
        const long long a = k + mrpctl_stream_integer((uint64_t)keys[l], (uint64_t)k, d_min[l], d);
        if (a >= k0 && k > latest[(a % (d + 1)) * MRPCTL_W + l]) latest[(a % (d + 1)) * MRPCTL_W + l] = k;
      }
  }
  for (k = k0; k < k1; ++k) {
    double* now = buffers[now_index];
    double* next = buffers[now_index ^ 1];
    const double* delayed = d == 0 ? history : k < d ? history + MRPCTL_COLUMN * k : ring + MRPCTL_COLUMN * delayed_slot;
    if (jitter || used) { /* each lane its own j*(k): its values gathered from its column */
      long long chosen[MRPCTL_W];
      if (jitter) { /* the block's schedule (mrpctl_lane_schedule) */
        if (k == schedule_k1) {
          const long long count = k1 - k < MRPCTL_NOISE_BLOCK ? k1 - k : MRPCTL_NOISE_BLOCK;
          mrpctl_lane_schedule(keys, d_min, newest, latest, d, k, count, slot, schedule);
          schedule_k0 = k;
          schedule_k1 = k + count;
        }
        for (l = 0; l < MRPCTL_W; ++l) chosen[l] = schedule[(k - schedule_k0) * MRPCTL_W + l];
      } else {
        for (l = 0; l < MRPCTL_W; ++l) chosen[l] = used[(k - k0) * MRPCTL_W + l];
      }
      for (l = 0; l < MRPCTL_W; ++l) {
        const long long j = chosen[l];
        const double* column;
        if (j < 0) {
          column = history + MRPCTL_COLUMN * (j + d);
        } else { /* slot of j = k's slot - (k - j), 1 <= k - j <= d */
          long long used_slot = slot - (k - j);
          if (used_slot < 0) used_slot += d + 1;
          column = ring + MRPCTL_COLUMN * used_slot;
        }
        for (m = 0; m < MRPCTL_MEASURED; ++m) gathered[m * MRPCTL_W + l] = column[m * MRPCTL_W + l];
      }
      delayed = gathered;
    }
    if (noise_keys && k == noise_k1) { /* the next block of every lane's noise rows */
      const long long count = k1 - k < MRPCTL_NOISE_BLOCK ? k1 - k : MRPCTL_NOISE_BLOCK;
      mrpctl_lane_noise(noise_keys, sigmas, k, count, noise_block);
      noise_k0 = k;
      noise_k1 = k + count;
    }
    for (i = 0; i < MRPCTL_N_IN; ++i) {
      if (mrpctl_in_role[i] == MRPCTL_ROLE_CARRIED) arg[i] = now + mrpctl_in_offset[i] * MRPCTL_W;
      else if (mrpctl_in_role[i] == MRPCTL_ROLE_DELAYED) arg[i] = delayed;
      else if (mrpctl_in_role[i] == MRPCTL_ROLE_STREAMED) arg[i] = stream + stream_stride * (k - k0) + mrpctl_in_offset[i];
      else if (mrpctl_in_role[i] == MRPCTL_ROLE_NOISE) arg[i] = noise_block + 6 * MRPCTL_W * (k - noise_k0);
    }
    for (i = 0; i < MRPCTL_N_OUT; ++i) {
      if (mrpctl_out_role[i] == MRPCTL_ROLE_CARRIED) res[i] = next + mrpctl_out_offset[i] * MRPCTL_W;
      else if (mrpctl_out_role[i] == MRPCTL_ROLE_MEASUREMENT) res[i] = ring + MRPCTL_COLUMN * slot;
    }
    mrpctl_lanes_sample(arg, res);
    if (++slot > d) slot = 0;
    if (k >= d && ++delayed_slot > d) delayed_slot = 0;
    now_index ^= 1;
  }
  memcpy(carried, buffers[now_index], sizeof(buffers[0]));
  return 0;
}
