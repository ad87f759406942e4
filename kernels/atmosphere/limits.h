/* limits.h — sizes of the atmosphere kernels' quadratures and work tables, shared by the
 * kernels (atmosphere.cl), the config checks and the host's device-memory estimate, so the
 * host never repeats them as literals. Plain integers: no `real`, safe to include anywhere.
 */
#ifndef SPECBAKE_ATMOSPHERE_LIMITS_H
#define SPECBAKE_ATMOSPHERE_LIMITS_H

#define ATMOSPHERE_NU_LIMIT 64        /* largest `sizes.scattering.nu` the kernels accept (NU_MAX) */
#define TRANSMITTANCE_STEPS 500       /* trapezoid intervals of the optical-depth integral */
#define SCATTERING_STEPS 50           /* trapezoid intervals along a view ray (single/multiple) */
#define DENSITY_SPHERE_STEPS 16       /* φ pairs of the scattering density's sphere rule (32 φ) */
#define DENSITY_THETA_MAX 128         /* largest `quadrature.density_theta` */
#define IRRADIANCE_HEMISPHERE_STEPS 32
#define RAY_FIXED 8                   /* fixed values per ray sample before the NCH transmittances */
#define INC_FIXED 6                   /* ground flag, distance, n_z, 1/|n|, cos θ, sin θ */

#endif
