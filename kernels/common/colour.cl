/* colour.cl — CIE colorimetry shared by the kernels and the C++ reference.
 *
 *   xyz_to_lab   CIE 1976 L*a*b* from XYZ relative to a white (Xn, Yn, Zn), CIE 15:2004 §8.2.1
 *                (the linear segment below (6/29)^3 included). Units: XYZ in any common scale.
 *   cmf_lerp     colour-matching functions x̄ȳz̄ at any λ from a 1 nm table: linear between rows,
 *                0 outside the table (used by every kind that integrates spectra).
 *   ciede2000    CIE DE2000 colour difference, CIE 142-2001, with kL = kC = kH = 1, written
 *                after G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula:
 *                implementation notes, supplementary test data, and mathematical observations",
 *                Color Res. Appl. 30(1), 2005 (eqs. 2–22; hue angles in degrees, h = 0 when a' = b' = 0).
 */
#ifndef SPECBAKE_COLOUR_CL
#define SPECBAKE_COLOUR_CL
#include "common/real.h"

/* x̄ȳz̄ at lambda_nm (nm) from a table of `count` rows [x̄, ȳ, z̄] at 1 nm steps from first_nm. */
FN void cmf_lerp(GLOBAL const real* table, int count, real first_nm, real lambda_nm, real* xyz) {
  REQUIRE(count >= 2);
  const real t = lambda_nm - first_nm;
  xyz[0] = xyz[1] = xyz[2] = R(0.0);
  if (!(t >= R(0.0)) || t > (real)(count - 1)) return;
  int i = (int)floor(t);
  if (i > count - 2) i = count - 2;
  const real f = t - (real)i;
  for (int c = 0; c < 3; ++c) xyz[c] = (R(1.0) - f) * table[3 * i + c] + f * table[3 * (i + 1) + c];
}


FN real lab_f(real t) {
  const real d = R(6.0) / R(29.0);
  return t > d * d * d ? cbrt(t) : t / (R(3.0) * d * d) + R(4.0) / R(29.0);
}

FN void xyz_to_lab(real X, real Y, real Z, real Xn, real Yn, real Zn, real* L, real* a, real* b) {
  const real fx = lab_f(X / Xn), fy = lab_f(Y / Yn), fz = lab_f(Z / Zn);
  *L = R(116.0) * fy - R(16.0);
  *a = R(500.0) * (fx - fy);
  *b = R(200.0) * (fy - fz);
}

FN real deg_to_rad(real d) { return d * R(3.14159265358979323846) / R(180.0); }
FN real rad_to_deg(real r) { return r * R(180.0) / R(3.14159265358979323846); }

FN real ciede2000(real L1, real a1, real b1, real L2, real a2, real b2) {
  const real C1 = sqrt(a1 * a1 + b1 * b1), C2 = sqrt(a2 * a2 + b2 * b2);
  const real Cbar = R(0.5) * (C1 + C2);
  const real Cbar7 = pow(Cbar, R(7.0));
  const real G = R(0.5) * (R(1.0) - sqrt(Cbar7 / (Cbar7 + R(6103515625.0)))); /* 25^7 */
  const real a1p = (R(1.0) + G) * a1, a2p = (R(1.0) + G) * a2;
  const real C1p = sqrt(a1p * a1p + b1 * b1), C2p = sqrt(a2p * a2p + b2 * b2);
  real h1p = (a1p == R(0.0) && b1 == R(0.0)) ? R(0.0) : rad_to_deg(atan2(b1, a1p));
  real h2p = (a2p == R(0.0) && b2 == R(0.0)) ? R(0.0) : rad_to_deg(atan2(b2, a2p));
  if (h1p < R(0.0)) h1p += R(360.0);
  if (h2p < R(0.0)) h2p += R(360.0);

  const real dLp = L2 - L1;
  const real dCp = C2p - C1p;
  real dhp = R(0.0);
  if (C1p * C2p != R(0.0)) {
    dhp = h2p - h1p;
    if (dhp > R(180.0)) dhp -= R(360.0);
    else if (dhp < R(-180.0)) dhp += R(360.0);
  }
  const real dHp = R(2.0) * sqrt(C1p * C2p) * sin(deg_to_rad(R(0.5) * dhp));

  const real Lbarp = R(0.5) * (L1 + L2);
  const real Cbarp = R(0.5) * (C1p + C2p);
  real hbarp = h1p + h2p;
  if (C1p * C2p != R(0.0)) {
    if (fabs(h1p - h2p) <= R(180.0)) hbarp = R(0.5) * (h1p + h2p);
    else if (h1p + h2p < R(360.0)) hbarp = R(0.5) * (h1p + h2p + R(360.0));
    else hbarp = R(0.5) * (h1p + h2p - R(360.0));
  }
  const real T = R(1.0) - R(0.17) * cos(deg_to_rad(hbarp - R(30.0))) + R(0.24) * cos(deg_to_rad(R(2.0) * hbarp)) +
                 R(0.32) * cos(deg_to_rad(R(3.0) * hbarp + R(6.0))) - R(0.20) * cos(deg_to_rad(R(4.0) * hbarp - R(63.0)));
  const real dtheta = R(30.0) * exp(-((hbarp - R(275.0)) / R(25.0)) * ((hbarp - R(275.0)) / R(25.0)));
  const real Cbarp7 = pow(Cbarp, R(7.0));
  const real RC = R(2.0) * sqrt(Cbarp7 / (Cbarp7 + R(6103515625.0)));
  const real Lm50 = (Lbarp - R(50.0)) * (Lbarp - R(50.0));
  const real SL = R(1.0) + R(0.015) * Lm50 / sqrt(R(20.0) + Lm50);
  const real SC = R(1.0) + R(0.045) * Cbarp;
  const real SH = R(1.0) + R(0.015) * Cbarp * T;
  const real RT = -sin(deg_to_rad(R(2.0) * dtheta)) * RC;
  const real tL = dLp / SL, tC = dCp / SC, tH = dHp / SH;
  return sqrt(tL * tL + tC * tC + tH * tH + RT * tC * tH);
}

#endif
