/* truth_kernels.cl — OpenCL entry point of the path-traced atmosphere truth: one work item per
 * (point, batch of walks). The maths is in path_tracer.cl (and atmosphere.cl).
 * Built with -DNCH=3 (channels per launch) and real = double where the device has
 * cl_khr_fp64 (-DSPECBAKE_REAL_DOUBLE), else float. */
#include "atmosphere/atmosphere.cl"
#include "atmosphere/path_tracer.cl"

/* Work item id → point p = id / batch_stride (point point_base + p of the request) and the
 * j-th batch of this launch, j = id % batch_stride: channel c of the group walks its batch
 * batch_base[p][c] + j when j < batch_count[p][c] ([points][NCH] each); out holds
 * [points][batch_stride][TRUTH_OUT_STRIDE], pilot (a pilot launch)
 * [points][batch_stride][paths_per_batch][NCH][TRUTH_PILOT_STRIDE]. */
__kernel void truth_trace(AtmosphereParameters a, __global const real* points, __global const real* node_t,
                          __global const real* node_tau, __global const real* node_cdf,
                          __global const real* medium, int point_count, int point_base, int nodes,
                          __global const int* batch_base, __global const int* batch_count, int batch_stride,
                          int paths_per_batch, int max_orders, int split_order, int next_sun, int order1,
                          uint seed_lo, uint seed_hi, int channel_base, int channels, __global const real* cells,
                          int mode, __global real* out, __global real* pilot) {
  const int id = get_global_id(0);
  if (id >= point_count * batch_stride) return;
  const int p = id / batch_stride, j = id % batch_stride;
  truth_trace_item(&a, points, node_t, node_tau, node_cdf, medium, nodes, p, point_base, j, batch_base + p * NCH,
                   batch_count + p * NCH, paths_per_batch, max_orders, split_order, next_sun, order1, seed_lo, seed_hi,
                   channel_base, channels, cells, mode, out + (p * batch_stride + j) * TRUTH_OUT_STRIDE,
                   pilot + (mode == TRUTH_MODE_PILOT ? (p * batch_stride + j) * paths_per_batch * NCH * TRUTH_PILOT_STRIDE : 0));
}
