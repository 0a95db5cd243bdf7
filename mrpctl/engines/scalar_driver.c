/* mrpctl: the horizon driver appended to CasADi's C code of one engine sample.
 *
 * MRPCTL_SAMPLE is the generated sample function
 *   sample(x, memory, stats, x_delayed, K, parameters[, J, J_inv][, flight])
 *     -> (x_next, memory_next, stats_next, x_meas, u, switched)
 * and MRPCTL_RUN the exported driver; both, and the sizes below, are #defined by
 * mrpctl/engines/scalar.py in front of this file.
 *
 * MRPCTL_RING_WIDTH is the width of one ring entry (6: m_k; 12 for the predictor sample: m_k and the
 * controller's model state z_k); with MRPCTL_RING_OUTPUT the sample has a seventh output, the ring
 * entry, apart from x_meas (the flight and predictor samples), and with MRPCTL_SENSOR a per-sample
 * noise input, generated here: row k is (sigma[0] n_a(3k + c), sigma[1] n_r(3k + c)), c = 0, 1, 2, with the
 * normals of noise.c (included in front of this file) of the streams noise_key[0] (attitude) and
 * noise_key[1] (rate), drawn MRPCTL_NOISE_BLOCK samples at a time by mrpctl_normal_rows; a zero sigma gives exact zeros (the NumPy mirror: mrpctl.flight.SensorModel.noise_rows). With MRPCTL_RECORD_OUTPUT (its output index) the flight sample's record of
 * MRPCTL_RECORD_WIDTH numbers per sample is copied to kept_records like u (NULL: not kept); with
 * MRPCTL_TORQUE_INPUT (its input index) the sample reads a per-sample torque, row k - k0 of torque, and with
 * MRPCTL_REFERENCE_INPUT (its input index; the next input is the reference at the error time) a tracked
 * reference, row k - k0 of reference and row max(k - k0 - held, 0) of reference_error, held =
 * reference_control[0] (the first samples of a run whose error time is before t = 0 take row 0, read in place); with
 * reference_control[3] nonzero the driver checks row k - k0 of reference before sample k (every entry finite,
 * |sigma_RN|^2 <= MRPCTL_REFERENCE_BOUND: the rows of an array reference, checked as they are read instead of in a
 * pass of their own) and stops before the first bad one, k in reference_control[4] (else -1). With
 * MRPCTL_TRUE_ERROR_INPUT the kept records are
 * MRPCTL_RECORD_WIDTH wide and end with the true sigma_B/R at t_k, computed here for the kept samples only by the
 * generated MRPCTL_TRUE_ERROR(x_meas, reference) from the kept x_meas and the row of t_k (the sample's record fills
 * the first MRPCTL_TRUE_ERROR_OFFSET numbers). With MRPCTL_LAGGED_SETTLING the sample folds the statistics of
 * sample k - d (its controller's error is that sample's true error) and MRPCTL_TAIL_RUN folds those of the last
 * samples j0 .. j1-1 of a run from their ring entries (slot j mod ring_size) and rows (t_j) by MRPCTL_TAIL; MRPCTL_RUN
 * folds them itself when the run ends in its call (at sample reference_control[1], the run's n, or by diverging) and
 * the rows of the last d samples are in the slice's reference, and then sets reference_control[2] to 1 (else the
 * caller folds them by MRPCTL_TAIL_RUN). With MRPCTL_TRUE_ERROR_INPUT, MRPCTL_TRUE_ERROR_ONE(x_meas, row, out) is
 * MRPCTL_TRUE_ERROR of one sample (the controller's memory at k = 0). With MRPCTL_DELAY_INPUT (its input index) the
 * sample reads d, as a casadi_real, from that input (the lagged statistics' k - d). With MRPCTL_STATS_FIRST the sample's first three outputs are
 * stats_next, x_next, memory_next (the order of its generated code), else x_next, memory_next, stats_next.
 *
 * MRPCTL_RUN runs samples k0 .. k1-1 of one run. It only moves pointers: x, memory and
 * stats alternate between two buffers; the sample writes m_k into a ring of ring_size
 * columns (slot k mod ring_size) from which m_{k-d} is read (from the history for k < d);
 * every keep_every-th m_k and u_k are copied to the kept arrays (column k / keep_every;
 * with keep_every = 1 the caller may pass the kept array itself as a ring of n columns),
 * the switch flags of the slice go to switched[k - k0]. A time-varying delay: either `used` (j*(k) of
 * each sample of the slice, a given delay sequence, from NumPy) or `jitter` (in-out: key bits, d_min, j*(k0 - 1),
 * then d + 1 ring entries), whose delays d_j = integer(key, j) in [d_min, d] come from noise.c and whose
 * schedule is computed here, O(1) per sample: measurement j is registered at its arrival slot
 * latest[(j + d_j) mod (d + 1)] = max(., j), and j*(k) = max(j*(k - 1), latest[k mod (d + 1)], min(k - d, -1));
 * the slot is then cleared. The pending measurements j in [k0 - d, k0) are registered again at the start of a
 * slice (their delays are a function of j), so only j*(k0 - 1) is carried. The delay used k - j*(k) of kept
 * samples goes to kept_delays (when not NULL). The arithmetic is the sample's,
 * unchanged: a run cut into slices gives the same bits as one call.
 *
 * Returns the number of samples done: k1 - k0, or fewer when the run diverged (the last
 * one done is the diverging sample, whose measurement is still a good state); -1 when the
 * sample function failed. state (x, memory, stats) holds the state after the last sample.
 */
#if MRPCTL_STATS_FIRST
#define MRPCTL_OUT_X 1
#define MRPCTL_OUT_MEMORY 2
#define MRPCTL_OUT_STATS 0
#else
#define MRPCTL_OUT_X 0
#define MRPCTL_OUT_MEMORY 1
#define MRPCTL_OUT_STATS 2
#endif

/* two doubles, for the reference rows' check (SSE2's pairs; the same IEEE subtractions and additions) */
typedef double mrpctl_pair __attribute__((vector_size(16)));

/* samples of noise drawn at a time (6 doubles each: 3 KB on the stack) */
#define MRPCTL_NOISE_BLOCK 64

#if MRPCTL_ROTATION_INPUT
/* theta -> sigma(theta) of the first three numbers of each of `rows` noise rows (6 wide), in place, by the generated
   MRPCTL_ROTATION; nonzero when it failed */
static int mrpctl_rotation_rows(casadi_real* rows_data, long long rows) {
  const casadi_real* arg[1];
  casadi_real* res[1];
  casadi_int iw[MRPCTL_ROTATION_SZ_IW];
  casadi_real w[MRPCTL_ROTATION_SZ_W];
  casadi_real out[3];
  long long j;
  res[0] = out;
  for (j = 0; j < rows; ++j) {
    casadi_real* row = rows_data + 6 * j;
    arg[0] = row;
    if (MRPCTL_ROTATION(arg, res, iw, w, 0)) return 1;
    row[0] = out[0];
    row[1] = out[1];
    row[2] = out[2];
  }
  return 0;
}
#endif

#if MRPCTL_LAGGED_SETTLING
CASADI_SYMBOL_EXPORT long long MRPCTL_TAIL_RUN(casadi_real* stats, const casadi_real* ring, long long ring_size,
    const casadi_real* rows, long long j0, long long j1) {
  const casadi_real* arg[4];
  casadi_real* res[1];
  casadi_int iw[MRPCTL_TAIL_SZ_IW];
  casadi_real w[MRPCTL_TAIL_SZ_W];
  casadi_real out[MRPCTL_STATS_SIZE];
  casadi_real index;
  long long j;
  int i;
  res[0] = out;
  for (j = j0; j < j1; ++j) {
    index = (casadi_real)j;
    arg[0] = stats;
    arg[1] = ring + MRPCTL_RING_WIDTH * (j % ring_size);
    arg[2] = rows + 9 * (j - j0);
    arg[3] = &index;
    if (MRPCTL_TAIL(arg, res, iw, w, 0)) return -1;
    for (i = 0; i < MRPCTL_STATS_SIZE; ++i) stats[i] = out[i];
  }
  return j1 - j0;
}
#endif

#if MRPCTL_TRUE_ERROR_INPUT
CASADI_SYMBOL_EXPORT int MRPCTL_TRUE_ERROR_ONE(const casadi_real* x_meas, const casadi_real* row, casadi_real* out) {
  const casadi_real* arg[2];
  casadi_real* res[1];
  casadi_int iw[MRPCTL_TRUE_ERROR_SZ_IW];
  casadi_real w[MRPCTL_TRUE_ERROR_SZ_W];
  arg[0] = x_meas;
  arg[1] = row;
  res[0] = out;
  return MRPCTL_TRUE_ERROR(arg, res, iw, w, 0);
}
#endif

CASADI_SYMBOL_EXPORT long long MRPCTL_RUN(casadi_real* state, const casadi_real* history,
    long long history_stride, const casadi_real* gain, const casadi_real* parameters,
    const casadi_real* inertia, const casadi_real* inertia_inverse, const casadi_real* flight,
    const casadi_real* noise, const unsigned long long* noise_key, const casadi_real* torque,
    long long torque_stride, const casadi_real* reference, const casadi_real* reference_error, long long* reference_control, const long long* used, long long* jitter, long long* kept_delays, long long k0, long long k1,
    long long d, casadi_real* ring, long long ring_size, long long keep_every,
    casadi_real* kept_measurements, casadi_real* kept_u, casadi_real* switched, casadi_real* kept_records) {
  const casadi_real* arg[MRPCTL_SZ_ARG];
  casadi_real* res[MRPCTL_SZ_RES];
  casadi_int iw[MRPCTL_SZ_IW];
  casadi_real w[MRPCTL_SZ_W];
  casadi_real buffers[2][MRPCTL_STATE];
  const long long width = MRPCTL_RING_WIDTH;
  long long k, slot, delayed_slot = 0, phase = 1, kept_column = 0;
  int i, now_index = 0;
  long long newest = 0, j_used = 0, d_min = 0;
  long long* latest = 0;
  long long jitter_slot = 0;
  uint64_t jitter_key = 0;
  for (i = 0; i < MRPCTL_STATE; ++i) buffers[0][i] = state[i];
  if (jitter) {
    jitter_key = (uint64_t)jitter[0];
    d_min = jitter[1];
    newest = jitter[2];
    latest = jitter + 3;
    for (i = 0; i <= d; ++i) latest[i] = LLONG_MIN;
    for (k = k0 - d > 0 ? k0 - d : 0; k < k0; ++k) {
      const long long a = k + mrpctl_stream_integer(jitter_key, (uint64_t)k, d_min, d);
      if (a >= k0 && k > latest[a % (d + 1)]) latest[a % (d + 1)] = k;
    }
  }
  slot = k0 % ring_size;
  if (jitter) jitter_slot = k0 % (d + 1);
  if (k0 >= d) delayed_slot = (k0 - d) % ring_size;
  if (keep_every > 0) {
    phase = k0 % keep_every;
    kept_column = (k0 + keep_every - 1) / keep_every;
  }
  arg[4] = gain;
  arg[5] = parameters;
#if MRPCTL_INERTIA_INPUT
  arg[6] = inertia;
  arg[7] = inertia_inverse;
#else
  (void)inertia;
  (void)inertia_inverse;
#endif
#if MRPCTL_FLIGHT_INPUT
  arg[6 + 2 * MRPCTL_INERTIA_INPUT] = flight;
#else
  (void)flight;
#endif
#if MRPCTL_SENSOR
  /* the noise rows of MRPCTL_NOISE_BLOCK samples at a time, drawn in mrpctl_normal_rows' own loop:
     rows k in [noise_k0, noise_k1) are in noise_block */
  casadi_real noise_block[MRPCTL_NOISE_BLOCK * 6];
  long long noise_k0 = k0, noise_k1 = k0;
#else
  (void)noise;
  (void)noise_key;
#endif
#if !MRPCTL_TORQUE_INPUT
  (void)torque;
  (void)torque_stride;
#endif
#if !MRPCTL_RECORD_OUTPUT
  (void)kept_records;
#endif
#if MRPCTL_DELAY_INPUT
  /* the lagged statistics take sample k - d: d is an input of the sample (one library for every d) */
  const casadi_real delay_value = (casadi_real)d;
  arg[MRPCTL_DELAY_INPUT] = &delay_value;
#endif
#if MRPCTL_REFERENCE_INPUT
  const long long held = reference_control ? reference_control[0] : 0;
  const int check_rows = reference_control && reference_control[3];
  if (check_rows) reference_control[4] = -1;
#else
  (void)reference;
  (void)reference_error;
  (void)reference_control;
#endif
  for (k = k0; k < k1; ++k) {
    casadi_real* now = buffers[now_index];
    casadi_real* next = buffers[now_index ^ 1];
    int kept = keep_every > 0 && phase == 0;
    arg[0] = now;
    arg[1] = now + MRPCTL_X;
    arg[2] = now + MRPCTL_X_MEMORY;
    if (d == 0) {
      arg[3] = history;
    } else {
      arg[3] = k < d ? history + history_stride * k : ring + width * delayed_slot;
    }
    if (jitter) {
      /* seeded jitter: measurement k arrives at k + d_k (d_k >= d_min >= 1, so never at k itself) */
      /* s = k mod (d + 1) and arrival = (k + d_k) mod (d + 1) by counting, not by 64-bit division */
      const long long s = jitter_slot;
      long long arrival = s + mrpctl_stream_integer(jitter_key, (uint64_t)k, d_min, d);
      if (arrival > d) arrival -= d + 1;
      if (latest[s] > newest) newest = latest[s];
      if (k - d > newest) newest = k - d; /* the history sample k - d arrives at k */
      latest[s] = LLONG_MIN;
      latest[arrival] = k; /* = max(latest[arrival], k): every measurement registered before is older than k */
      j_used = newest;
      if (++jitter_slot > d) jitter_slot = 0;
    } else if (used) {
      j_used = used[k - k0]; /* a given delay sequence: j*(k) from NumPy */
    }
    if (jitter || used) {
      /* a time-varying delay: the newest arrived measurement j*(k) in [k - d, k - 1] (d = d_max) */
      if (j_used < 0) {
        arg[3] = history + history_stride * (j_used + d);
      } else {
        /* slot of j*(k) = (k - (k - j*(k))) mod ring_size from k's slot: 1 <= k - j*(k) <= d < ring_size */
        long long used_slot = slot - (k - j_used);
        if (used_slot < 0) used_slot += ring_size;
        arg[3] = ring + width * used_slot;
      }
      if (kept && kept_delays) kept_delays[kept_column] = k - j_used;
    }
    res[MRPCTL_OUT_X] = next;
    res[MRPCTL_OUT_MEMORY] = next + MRPCTL_X;
    res[MRPCTL_OUT_STATS] = next + MRPCTL_X_MEMORY;
#if MRPCTL_SENSOR
    if (k == noise_k1) {
      const long long rows = k1 - k < MRPCTL_NOISE_BLOCK ? k1 - k : MRPCTL_NOISE_BLOCK;
      mrpctl_normal_rows(noise_key[0], (uint64_t)(3 * k), rows, noise[0], noise_block, 6);
      mrpctl_normal_rows(noise_key[1], (uint64_t)(3 * k), rows, noise[1], noise_block + 3, 6);
#if MRPCTL_ROTATION_INPUT
      /* the sample takes the attitude noise's MRP sigma(theta): computed here for the block by the sensor's own
         generated function (a zero 1 sigma leaves the exact zeros it gives for theta = 0) */
      if (noise[0] > 0.0 && mrpctl_rotation_rows(noise_block, rows)) return -1;
#endif
      noise_k0 = k;
      noise_k1 = k + rows;
    }
    arg[7 + 2 * MRPCTL_INERTIA_INPUT] = noise_block + 6 * (k - noise_k0);
#endif
#if MRPCTL_TORQUE_INPUT
    /* a per-sample disturbance w_k (the flight sample's last input) */
    arg[MRPCTL_TORQUE_INPUT] = torque + torque_stride * (k - k0);
#endif
#if MRPCTL_REFERENCE_INPUT
    /* a tracked reference: row k - k0 of the slice's reference at t_k and the row of the controller's error time
       (9 each): row 0 for the first `held` samples, then one row further a sample */
    arg[MRPCTL_REFERENCE_INPUT] = reference + 9 * (k - k0);
    arg[MRPCTL_REFERENCE_INPUT + 1] = reference_error + 9 * (k - k0 > held ? k - k0 - held : 0);
    if (check_rows) {
      /* row k: x - x is 0 for a finite x and NaN otherwise, and NaN fails the comparison (so does a NaN sigma) */
      const casadi_real* r = reference + 9 * (k - k0);
      mrpctl_pair a, b, c, z;
      memcpy(&a, r + 3, sizeof a);
      memcpy(&b, r + 5, sizeof b);
      memcpy(&c, r + 7, sizeof c);
      z = ((a - a) + (b - b)) + (c - c); /* two lanes at a time */
      if (!(((r[0] * r[0] + r[1] * r[1]) + r[2] * r[2]) + (z[0] + z[1]) <= MRPCTL_REFERENCE_BOUND)) {
        reference_control[4] = k;
        break;
      }
    }
#endif
#if MRPCTL_RING_OUTPUT
    /* the flight and predictor samples: the sensor's measurement (and the model state) go to the ring,
       the true state to the kept array */
    res[3] = kept ? kept_measurements + 6 * kept_column : 0; /* NULL: CasADi's code skips the output */
    res[6] = ring + width * slot;
#else
    res[3] = ring + 6 * slot;
#endif
    res[4] = kept ? kept_u + 3 * kept_column : 0;
    res[5] = switched ? switched + (k - k0) : 0;
#if MRPCTL_RECORD_OUTPUT
    /* the flight sample's per-sample record (h, sigma_c), kept like u */
    res[MRPCTL_RECORD_OUTPUT] = kept && kept_records ? kept_records + MRPCTL_RECORD_WIDTH * kept_column : 0;
#endif
    if (MRPCTL_SAMPLE(arg, res, iw, w, 0)) return -1;
#if MRPCTL_TRUE_ERROR_INPUT
    if (kept && kept_records) {
      /* the true sigma_B/R closing the kept record: from x_meas (the kept column with a ring output, else the ring
         entry the sample just wrote) and the reference row of t_k */
      const casadi_real* error_arg[2];
      casadi_real* error_res[1];
      casadi_int error_iw[MRPCTL_TRUE_ERROR_SZ_IW];
      casadi_real error_w[MRPCTL_TRUE_ERROR_SZ_W];
      error_arg[0] = MRPCTL_RING_OUTPUT ? kept_measurements + 6 * kept_column : ring + 6 * slot;
      error_arg[1] = reference + 9 * (k - k0);
      error_res[0] = kept_records + MRPCTL_RECORD_WIDTH * kept_column + MRPCTL_TRUE_ERROR_OFFSET;
      if (MRPCTL_TRUE_ERROR(error_arg, error_res, error_iw, error_w, 0)) return -1;
    }
#endif
    if (kept) {
      if (!MRPCTL_RING_OUTPUT && kept_measurements != ring)
        for (i = 0; i < 6; ++i) kept_measurements[6 * kept_column + i] = ring[6 * slot + i];
      ++kept_column;
    }
    if (keep_every > 0 && ++phase == keep_every) phase = 0;
    if (++slot == ring_size) slot = 0;
    if (k >= d && ++delayed_slot == ring_size) delayed_slot = 0;
    now_index ^= 1;
    if (next[MRPCTL_X_MEMORY + MRPCTL_S_DIVERGED] >= 0) {
      ++k;
      break;
    }
  }
  for (i = 0; i < MRPCTL_STATE; ++i) state[i] = buffers[now_index][i];
  if (jitter) jitter[2] = newest;
#if MRPCTL_LAGGED_SETTLING
  /* the run ended here (its last sample, or the diverging one): the statistics of its last d samples, whose rows
     t_j are in this slice's reference when j0 >= k0 */
  if (reference_control && reference_control[1] >= 0 && !(check_rows && reference_control[4] >= 0) &&
      (k == reference_control[1] || state[MRPCTL_X_MEMORY + MRPCTL_S_DIVERGED] >= 0)) {
    const long long j0 = k - d > 0 ? k - d : 0;
    if (j0 >= k0) {
      if (MRPCTL_TAIL_RUN(state + MRPCTL_X_MEMORY, ring, ring_size, reference + 9 * (j0 - k0), j0, k) < 0) return -1;
      reference_control[2] = 1;
    }
  }
#endif
  return k - k0;
}
