/* dynid batch evaluation: one call evaluates a CasADi-generated function on N samples.
 *
 * Inputs are N x k row-major arrays (sample after sample, as numpy stores an (N, k) array); each
 * output is written row-major as N x rows x cols (numpy's (N, rows, cols)).  Only dense inputs and
 * outputs are supported (dynid generates them so).  Returns 0 on success, 1 if an output is not
 * dense, 2 if memory runs out, 3 if the generated function reports an error.
 */
#include <stdlib.h>
#include <string.h>

#include "@HEADER@"

typedef int (*dynid_fn)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int);
typedef int (*dynid_work_fn)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
typedef const casadi_int* (*dynid_sp_fn)(casadi_int);

static int dynid_batch(dynid_fn fn, dynid_work_fn work, dynid_sp_fn sp_in, dynid_sp_fn sp_out,
                       casadi_int n_in, casadi_int n_out, const double* const* in, double* const* out,
                       long long n) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w, i, k, r, c;
  casadi_int in_size[16], rows[16], cols[16];
  const casadi_real** arg;
  casadi_real** res;
  casadi_int* iw;
  casadi_real *w, *buf[16];
  int status = 0;
  if (n_in > 16 || n_out > 16) return 1;
  work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  /* The pointer arrays must be as long as the generated code reports, not just n_in / n_out. */
  arg = (const casadi_real**)calloc(sz_arg > n_in ? sz_arg : n_in, sizeof(*arg));
  res = (casadi_real**)calloc(sz_res > n_out ? sz_res : n_out, sizeof(*res));
  iw = (casadi_int*)malloc((sz_iw > 0 ? sz_iw : 1) * sizeof(*iw));
  w = (casadi_real*)malloc((sz_w > 0 ? sz_w : 1) * sizeof(*w));
  for (i = 0; i < n_out; ++i) buf[i] = NULL;
  if (!arg || !res || !iw || !w) { status = 2; goto done; }
  for (i = 0; i < n_in; ++i) {
    const casadi_int* sp = sp_in(i);
    in_size[i] = sp[0] * sp[1];
    if (sp[2] != 1 && !(sp[1] == 1 && sp[2] == 0 && sp[3] == sp[0])) { status = 1; goto done; }
  }
  for (i = 0; i < n_out; ++i) {
    const casadi_int* sp = sp_out(i);
    rows[i] = sp[0];
    cols[i] = sp[1];
    if (sp[2] != 1 && !(sp[1] == 1 && sp[2] == 0 && sp[3] == sp[0])) { status = 1; goto done; }
    buf[i] = (casadi_real*)malloc((rows[i] * cols[i] > 0 ? rows[i] * cols[i] : 1) * sizeof(casadi_real));
    if (!buf[i]) { status = 2; goto done; }
    res[i] = buf[i];
  }
  for (k = 0; k < n; ++k) {
    for (i = 0; i < n_in; ++i) arg[i] = in[i] + k * in_size[i];
    if (fn(arg, res, iw, w, 0)) { status = 3; goto done; }
    for (i = 0; i < n_out; ++i) {
      double* dst = out[i] + k * rows[i] * cols[i];
      const casadi_real* src = buf[i];
      if (cols[i] == 1) {
        memcpy(dst, src, rows[i] * sizeof(double));
      } else {
        for (r = 0; r < rows[i]; ++r)
          for (c = 0; c < cols[i]; ++c) dst[r * cols[i] + c] = src[c * rows[i] + r];
      }
    }
  }
done:
  for (i = 0; i < n_out; ++i) free(buf[i]);
  free(arg);
  free(res);
  free(iw);
  free(w);
  return status;
}
@WRAPPERS@
