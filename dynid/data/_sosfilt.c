/* Second-order sections run along the time axis of a time-major array, in place.
 *
 * x is (length, k) in C order: sample n of signal c at x[n * k + c].  Each section is the transposed
 * direct form II that scipy.signal.sosfilt runs, in the same order of operations, so that the values
 * agree with it to the bit (compiled without floating-point contraction):
 *
 *     y    = b0 x + z0
 *     z0'  = b1 x - a1 y + z1
 *     z1'  = b2 x - a2 y
 *
 * sos is (n_sections, 6) with a0 = 1; zi (n_sections, 2, k) holds the initial states and is updated to
 * the final ones.  reverse != 0 runs from the last sample to the first (the backward pass of a
 * zero-phase filter without reversed copies).  The loop over signals is innermost: the k signals of a
 * sample are independent and contiguous.
 */
#include <stddef.h>

void dynid_sosfilt(const double *sos, ptrdiff_t n_sections, double *x, ptrdiff_t length, ptrdiff_t k, double *zi,
                   int reverse)
{
    for (ptrdiff_t step = 0; step < length; ++step) {
        ptrdiff_t n = reverse ? length - 1 - step : step;
        double *row = x + n * k;
        for (ptrdiff_t s = 0; s < n_sections; ++s) {
            const double b0 = sos[6 * s], b1 = sos[6 * s + 1], b2 = sos[6 * s + 2];
            const double a1 = sos[6 * s + 4], a2 = sos[6 * s + 5];
            double *z0 = zi + 2 * s * k, *z1 = z0 + k;
            for (ptrdiff_t c = 0; c < k; ++c) {
                const double xc = row[c];
                const double y = b0 * xc + z0[c];
                z0[c] = b1 * xc - a1 * y + z1[c];
                z1[c] = b2 * xc - a2 * y;
                row[c] = y;
            }
        }
    }
}
