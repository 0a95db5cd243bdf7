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
 * rejected one scale times mrpctl_stream_normal_slow; else exact zeros), computed for the W lanes side by side so
 * that the compiler vectorises the first attempt across lanes (the same operations, lane by lane). */
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
  long long noise_k0 = k0, noise_k1 = k0;
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
      if (jitter) {
        /* the lanes' delays of measurement k (mrpctl_stream_integer's numbers, side by side: vectorised), then
           each lane's arrival ring */
        const uint64_t base = (((uint64_t)k << 12) + 1u) * UINT64_C(0x9E3779B97F4A7C15);
        long long arrivals[MRPCTL_W];
        for (l = 0; l < MRPCTL_W; ++l) {
          const uint64_t h = mrpctl_mix13((uint64_t)keys[l] + base);
          arrivals[l] = slot + d_min[l] + (long long)(((h >> 32) * (uint64_t)(d - d_min[l] + 1)) >> 32);
        }
        for (l = 0; l < MRPCTL_W; ++l) {
          long long* entry = latest + slot * MRPCTL_W + l;
          const long long arrival = arrivals[l] > d ? arrivals[l] - (d + 1) : arrivals[l];
          long long j = newest[l];
          if (*entry > j) j = *entry;
          if (k - d > j) j = k - d; /* the history sample k - d arrives at k */
          newest[l] = chosen[l] = j;
          *entry = LLONG_MIN;
          latest[arrival * MRPCTL_W + l] = k; /* every measurement registered before is older than k */
        }
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
