/* mrpctl: the W-lane horizon driver (appended to the code that mrpctl.engines.lanes emits).
 *
 * W runs advance in lockstep, one lane each, through n samples of the same sample Function.
 * Every buffer is structure-of-arrays: the nonzero j of a port for lane l is at [j * W + l].
 * The emitted code before this file defines
 *   MRPCTL_W, MRPCTL_N_IN, MRPCTL_N_OUT        lanes, the sample's input and output counts
 *   MRPCTL_CARRIED, MRPCTL_MEASURED            nonzeros carried from sample to sample (x, memory,
 *                                              stats, ...) and of the delayed measurement
 *   mrpctl_in_role[], mrpctl_in_offset[]       per input: MRPCTL_ROLE_CARRIED (offset into the
 *                                              carried block), MRPCTL_ROLE_DELAYED,
 *                                              MRPCTL_ROLE_CONSTANT (offset into the constants) or
 *                                              MRPCTL_ROLE_STREAMED (offset into a row of the
 *                                              stream: per sample, shared by the lanes)
 *   mrpctl_out_role[], mrpctl_out_offset[]     per output: MRPCTL_ROLE_CARRIED (the next value
 *                                              of a carried input), MRPCTL_ROLE_MEASUREMENT or
 *                                              MRPCTL_ROLE_DROPPED (not computed)
 *   mrpctl_lanes_sample(arg, res)              one sample for all W lanes
 * The loop is the scalar driver's (mrpctl/engines/scalar_driver.c without kept samples): the carried
 * block alternates between two buffers, the measurement m_k goes to a ring of d + 1 columns and
 * m_{k-d} is read back from it (from the history for k < d). Lanes that diverged or reached the
 * horizon are masked by the sample itself (every statistic freezes; only the sample
 * counter moves on), where the scalar driver stops such a run: mrpctl.engines.lanes.lane_stats sets
 * the counter of a diverged lane to the scalar driver's.
 */
#include <string.h>

#define MRPCTL_BLOCK (MRPCTL_CARRIED * MRPCTL_W)
#define MRPCTL_COLUMN (MRPCTL_MEASURED * MRPCTL_W)

/* Samples k0 .. k1-1 of W runs (a horizon is run in slices, so that the caller sees Ctrl-C and
 * its stop flag between them; slices give the same bits as one call).
 * carried: (MRPCTL_CARRIED, W), the values before sample k0 in and after sample k1-1 out.
 * constants: (constant nonzeros, W). history: (max(d, 1), MRPCTL_MEASURED, W), m_{-d}.. m_{-1}.
 * ring: (d + 1, MRPCTL_MEASURED, W), m_k in column k mod (d + 1); kept by the caller between
 * slices. stream: row k - k0 (stream_stride values a row; 0: the same row at every sample) holds
 * the streamed inputs of sample k, shared by the lanes (the flight sample's noise); may be null
 * when there are none. used: null for the constant delay d, else the newest arrived measurement
 * j*(k) in [k - d, k - 1] of each sample of the slice (a time-varying delay, d = d_max; shared
 * by the lanes), read from the ring, or from the history for j* < 0, as the scalar driver does.
 * Returns 0. */
__attribute__((visibility("default"))) int mrpctl_lanes_run(double* carried, const double* constants,
                                                            const double* history, long long k0, long long k1,
                                                            long long d, double* ring, const double* stream,
                                                            long long stream_stride, const long long* used) {
  static double* const unused = 0;
  double buffers[2][MRPCTL_BLOCK] __attribute__((aligned(64)));
  const double* arg[MRPCTL_N_IN];
  double* res[MRPCTL_N_OUT];
  long long k, slot = k0 % (d + 1), delayed_slot = k0 >= d ? (k0 - d) % (d + 1) : 0;
  int i, now_index = 0;
  memcpy(buffers[0], carried, sizeof(buffers[0]));
  for (i = 0; i < MRPCTL_N_IN; ++i) arg[i] = constants + mrpctl_in_offset[i] * MRPCTL_W;
  for (i = 0; i < MRPCTL_N_OUT; ++i) res[i] = unused;
  for (k = k0; k < k1; ++k) {
    double* now = buffers[now_index];
    double* next = buffers[now_index ^ 1];
    const double* delayed = d == 0 ? history : k < d ? history + MRPCTL_COLUMN * k : ring + MRPCTL_COLUMN * delayed_slot;
    if (used) {
      const long long j = used[k - k0];
      delayed = j < 0 ? history + MRPCTL_COLUMN * (j + d) : ring + MRPCTL_COLUMN * (j % (d + 1));
    }
    for (i = 0; i < MRPCTL_N_IN; ++i) {
      if (mrpctl_in_role[i] == MRPCTL_ROLE_CARRIED) arg[i] = now + mrpctl_in_offset[i] * MRPCTL_W;
      else if (mrpctl_in_role[i] == MRPCTL_ROLE_DELAYED) arg[i] = delayed;
      else if (mrpctl_in_role[i] == MRPCTL_ROLE_STREAMED) arg[i] = stream + stream_stride * (k - k0) + mrpctl_in_offset[i];
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

/* The lane count this library was built for (checked by the loader). */
__attribute__((visibility("default"))) int mrpctl_lanes_width(void) { return MRPCTL_W; }
