/* dynid batch evaluation: one call evaluates a CasADi-generated function on N samples.
 *
 * Inputs are N x k row-major arrays (sample after sample, as numpy stores an (N, k) array).  The
 * generated functions return dense outputs stored row-major, so sample k of output i is written
 * straight to out[i] + k * size_i: numpy's (N, rows, cols) layout, with no copy.  Returns 0 on
 * success, 1 if an input or output is not dense, 2 if memory runs out, 3 if the generated
 * function reports an error.
 */
#include <stdlib.h>

#include "@HEADER@"

typedef int (*dynid_fn)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int);
typedef int (*dynid_work_fn)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
typedef const casadi_int* (*dynid_sp_fn)(casadi_int);

/* Number of entries of a dense sparsity pattern, or -1 if it is not dense.  CasADi writes a dense
 * pattern compactly as {nrow, ncol, 1}; a dense column may also come in full CCS form. */
static casadi_int dynid_dense_size(const casadi_int* sp) {
  if (sp[2] == 1) return sp[0] * sp[1];
  if (sp[1] == 1 && sp[2] == 0 && sp[3] == sp[0]) return sp[0];
  return -1;
}

static int dynid_batch(dynid_fn fn, dynid_work_fn work, dynid_sp_fn sp_in, dynid_sp_fn sp_out,
                       casadi_int n_in, casadi_int n_out, const double* const* in, double* const* out,
                       long long n) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w, i, k;
  casadi_int in_size[16], out_size[16];
  const casadi_real** arg;
  casadi_real** res;
  casadi_int* iw;
  casadi_real* w;
  int status = 0;
  if (n_in > 16 || n_out > 16) return 1;
  for (i = 0; i < n_in; ++i)
    if ((in_size[i] = dynid_dense_size(sp_in(i))) < 0) return 1;
  for (i = 0; i < n_out; ++i)
    if ((out_size[i] = dynid_dense_size(sp_out(i))) < 0) return 1;
  work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  /* The pointer arrays must be as long as the generated code reports, not just n_in / n_out. */
  arg = (const casadi_real**)calloc(sz_arg > n_in ? sz_arg : n_in, sizeof(*arg));
  res = (casadi_real**)calloc(sz_res > n_out ? sz_res : n_out, sizeof(*res));
  iw = (casadi_int*)malloc((sz_iw > 0 ? sz_iw : 1) * sizeof(*iw));
  w = (casadi_real*)malloc((sz_w > 0 ? sz_w : 1) * sizeof(*w));
  if (!arg || !res || !iw || !w) {
    status = 2;
  } else {
    for (k = 0; k < n && status == 0; ++k) {
      for (i = 0; i < n_in; ++i) arg[i] = in[i] + k * in_size[i];
      for (i = 0; i < n_out; ++i) res[i] = out[i] + k * out_size[i];
      if (fn(arg, res, iw, w, 0)) status = 3;
    }
  }
  free(arg);
  free(res);
  free(iw);
  free(w);
  return status;
}
@WRAPPERS@
