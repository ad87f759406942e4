// The double reference path (kernels/atmosphere/atmosphere.cl compiled as C++) against the
// values of Bruneton's own reference implementation (refdata/atmosphere), using the
// reference's textures as inputs: this isolates our maths from our texture precomputation.
#include <gtest/gtest.h>

#include <cmath>

#include "atmosphere/npy.hpp"
#include "kinds/atmosphere/bake/reference.hpp"
#include "kinds/atmosphere/shader/render.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::atmosphere;
using specbake::testing::read_csv;
using specbake::testing::read_npy;

namespace {

std::string ref(const std::string& name) { return (specbake::testing::refdata_dir() / "atmosphere" / name).string(); }

struct Earth {
  AtmosphereSpec spec;
  Model m;
  Channels ch;
  ref3::AtmosphereParameters a;
  Earth() {
    spec.rayleigh_density[1] = DensityLayer{0, 1, -1.0 / 8.0, 0, 0};
    spec.mie_density[1] = DensityLayer{0, 1, -1.0 / 1.2, 0, 0};
    spec.ozone_density[0] = DensityLayer{25.0, 0, 0, 1.0 / 15.0, -2.0 / 3.0};
    spec.ozone_density[1] = DensityLayer{0, 0, 0, -1.0 / 15.0, 8.0 / 3.0};
    // the reference's quadratures and linear μ_s lookups (`quadrature: reference`)
    spec.use_reference_quadrature();
    m = model_of(spec);
    ch = channels_at(spec, {kLambdaR, kLambdaG, kLambdaB});
    a = ref3::make_parameters(m, ch);
  }
};

// Relative difference with an absolute floor (for values that are exactly 0 in the reference).
double rel(double got, double want, double floor) { return std::fabs(got - want) / (std::fabs(want) + floor); }

// Same functions, same double arithmetic, different length unit (km vs m), summation order and
// algebraically equal forms of the discriminants: a few ulps per operation over ≤ 500-term
// sums (~1e-13), amplified near the horizon where ρ² = r² − rb² and the ray discriminants
// cancel (r² ≈ 4e7 km² against differences of ~1e2 km²: ×1e5 at r − rb = 1 km). 1e-8 bounds
// that (the largest difference seen is 5e-9, on grazing rays 1 km above the ground).
constexpr double kSameMaths = 1e-8;
// Lookups in the reference's 3D textures as stored (float32 in refdata), against lookups the
// reference made in its float64 textures: the storage rounding, 2^-24 ≈ 6e-8 relative per
// texel, bounds the difference; 1e-6 leaves room for the interpolation's sums.
constexpr double kFloat32Storage = 1e-6;

// Rays (r, mu) near tangency to the ground: the distance along them is -r·mu ± sqrt(disc)
// with disc = r²(mu² − 1) + rb², a difference of two numbers ≈ r². Rounding moves disc by
// δ ≈ 8 ε r² (ε = 2^-53) between two algebraically equal forms, and the distance by
// min(sqrt(δ), δ / (2 sqrt|disc|)). Returns that distance uncertainty (km).
double tangent_sensitivity(double r, double mu, double rb) {
  const double disc = r * r * (mu * mu - 1.0) + rb * rb;
  const double delta = 8.0 * 1.1102230246251565e-16 * r * r;
  return std::min(std::sqrt(delta), delta / (2.0 * std::sqrt(std::fabs(disc)) + 1e-300));
}
bool is_tangent(double r, double mu, double rb) {
  const double disc = r * r * (mu * mu - 1.0) + rb * rb;
  return mu < 0.0 && std::fabs(disc) <= 8.0 * 1.1102230246251565e-16 * r * r;
}

}  // namespace

TEST(AtmosphereReference, ParametersMatchTheReferenceRun) {
  Earth e;
  const auto p = specbake::testing::read_json(ref("parameters.json"));
  for (int c = 0; c < 3; ++c) {
    // per km = 1000 × per m; the constants are the same decimal numbers: equal to rounding
    EXPECT_NEAR(e.ch.rayleigh_scattering[c] * 1e-3, p["rgb"]["rayleigh_scattering"][c].get<double>(), 1e-18);
    EXPECT_NEAR(e.ch.mie_extinction[c] * 1e-3, p["rgb"]["mie_extinction"][c].get<double>(), 1e-18);
    EXPECT_NEAR(e.ch.mie_scattering[c] * 1e-3, p["rgb"]["mie_scattering"][c].get<double>(), 1e-18);
    EXPECT_NEAR(e.ch.absorption_extinction[c] * 1e-3, p["rgb"]["absorption_extinction"][c].get<double>(), 1e-18);
    EXPECT_DOUBLE_EQ(e.ch.solar_irradiance[c], p["rgb"]["solar_irradiance"][c].get<double>());
  }
  EXPECT_NEAR(e.m.mu_s_min, p["mu_s_min"].get<double>(), 1e-15);
  // Spectral tables: the reference run's 47 samples (360..820 nm).
  const auto& sp = p["spectral"];
  for (std::size_t i = 0; i < sp["wavelengths_nm"].size(); ++i) {
    const double nm = sp["wavelengths_nm"][i].get<double>();
    EXPECT_DOUBLE_EQ(solar_irradiance_at(nm), sp["solar_irradiance"][i].get<double>()) << nm;
    EXPECT_NEAR(e.m.ozone_peak_number_density_per_m3 * ozone_cross_section_at(nm),
                sp["absorption_extinction"][i].get<double>(), 1e-12 * sp["absorption_extinction"][i].get<double>())
        << nm;
  }
}

TEST(AtmosphereReference, TransmittancePoints) {
  Earth e;
  const auto T = read_npy(ref("textures/transmittance.npy"));
  ASSERT_EQ(T.shape, (std::vector<std::int64_t>{64, 256, 3}));
  const auto csv = read_csv(ref("transmittance_points.csv"));
  ASSERT_GT(csv.rows.size(), 300u);
  for (const auto& row : csv.rows) {
    const double r = row[csv.col("r_m")] * 1e-3, mu = row[csv.col("mu")], h = r - e.m.bottom_radius_km;
    double t[3], tt[3], u, v;
    // rays through the planet keep the reference's literal altitude (no texture uses them)
    ref3::transmittance_to_top_integral(&e.a, h, mu, row[csv.col("ray_intersects_ground")] == 0.0, t);
    ref3::transmittance_to_top(&e.a, T.data.data(), h, mu, tt);
    ref3::transmittance_uv(&e.a, h, mu, &u, &v);
    // u grows past 1 below the horizon (up to ~16): relative agreement of the same maths
    EXPECT_LE(rel(u, row[csv.col("u")], 1e-300), kSameMaths) << "r=" << r << " mu=" << mu;
    EXPECT_NEAR(v, row[csv.col("v")], 1e-12) << "r=" << r << " mu=" << mu;
    // exactly tangent rays are classified by the sign of a rounding error: either answer is right
    if (!is_tangent(r, mu, e.m.bottom_radius_km))
      EXPECT_EQ(ref3::ray_hits_ground(&e.a, h, mu), row[csv.col("ray_intersects_ground")] != 0.0) << r << " " << mu;
    // A ray through the planet that touches the ground tangentially (r_min = rb up to rounding)
    // has a trapezoid sample at altitude 0 ± rounding, where the profiles switch layers (0 below
    // the ground, 1 above): that one sample's density is decided by rounding, in the reference
    // as here. It moves the optical depth by at most dx · Σ β_i (densities ≤ 1).
    const bool tangent_through = is_tangent(r, mu, e.m.bottom_radius_km) && row[csv.col("ray_intersects_ground")] != 0.0;
    const double dx = ref3::distance_to_top(&e.a, h, mu) / 500.0;
    const char* ch[3] = {"R", "G", "B"};
    for (int c = 0; c < 3; ++c) {
      const double one_sample =
          tangent_through ? std::expm1(dx * (e.ch.rayleigh_scattering[c] + e.ch.mie_extinction[c] +
                                            e.ch.absorption_extinction[c]))
                          : 0.0;
      EXPECT_LE(rel(t[c], row[csv.col(std::string("T_") + ch[c])], 1e-300), kSameMaths + one_sample)
          << "r=" << r << " mu=" << mu;
      EXPECT_LE(rel(tt[c], row[csv.col(std::string("T_tex_") + ch[c])], 1e-300), kSameMaths) << r << " " << mu;
    }
  }
}

TEST(AtmosphereReference, DirectIrradianceAndIrradianceLookups) {
  Earth e;
  const auto T = read_npy(ref("textures/transmittance.npy"));
  const auto D = read_npy(ref("textures/direct_irradiance.npy"));
  const auto E = read_npy(ref("textures/irradiance.npy"));
  const auto csv = read_csv(ref("direct_irradiance_points.csv"));
  ASSERT_EQ(csv.rows.size(), 100u);
  const char* ch[3] = {"R", "G", "B"};
  for (const auto& row : csv.rows) {
    const double r = row[csv.col("r_m")] * 1e-3, mu_s = row[csv.col("mu_s")], h = r - e.m.bottom_radius_km;
    double d[3], td[3], te[3], u, v;
    ref3::direct_irradiance(&e.a, T.data.data(), h, mu_s, d);
    ref3::get_irradiance(&e.a, D.data.data(), h, mu_s, td);
    ref3::get_irradiance(&e.a, E.data.data(), h, mu_s, te);
    ref3::irradiance_uv(&e.a, h, mu_s, &u, &v);
    EXPECT_NEAR(u, row[csv.col("u")], 1e-12);
    EXPECT_NEAR(v, row[csv.col("v")], 1e-12);
    for (int c = 0; c < 3; ++c) {
      EXPECT_LE(rel(d[c], row[csv.col(std::string("direct_") + ch[c])], 1e-300), kSameMaths) << r << " " << mu_s;
      EXPECT_LE(rel(td[c], row[csv.col(std::string("tex_direct_") + ch[c])], 1e-300), kSameMaths);
      EXPECT_LE(rel(te[c], row[csv.col(std::string("tex_sky_irradiance_") + ch[c])], 1e-300), kSameMaths);
    }
  }
}

TEST(AtmosphereReference, SingleScatteringPointsAndLookups) {
  Earth e;
  const auto T = read_npy(ref("textures/transmittance.npy"));
  const auto SR = read_npy(ref("textures/single_rayleigh_scattering.npy"));
  const auto SM = read_npy(ref("textures/single_mie_scattering.npy"));
  const auto S = read_npy(ref("textures/scattering.npy"));
  const auto csv = read_csv(ref("single_scattering_points.csv"));
  ASSERT_EQ(csv.rows.size(), 300u);
  const char* ch[3] = {"R", "G", "B"};
  double max_sr = 0, max_sm = 0, max_s = 0;
  for (std::size_t i = 0; i < SR.data.size(); ++i) {
    max_sr = std::max(max_sr, SR.data[i]);
    max_sm = std::max(max_sm, SM.data[i]);
    max_s = std::max(max_s, S.data[i]);
  }
  for (const auto& row : csv.rows) {
    const double r = row[csv.col("r_m")] * 1e-3, mu = row[csv.col("mu")], mu_s = row[csv.col("mu_s")],
                 nu = row[csv.col("nu")], h = r - e.m.bottom_radius_km;
    const int ground = row[csv.col("ray_r_mu_intersects_ground")] != 0.0;
    if (!is_tangent(r, mu, e.m.bottom_radius_km)) EXPECT_EQ(ref3::ray_hits_ground(&e.a, h, mu), ground) << r << " " << mu;
    const double length = row[csv.col("integration_length_m")] * 1e-3;
    const double dd = tangent_sensitivity(r, mu, e.m.bottom_radius_km);
    EXPECT_NEAR(ref3::distance_to_nearest_boundary(&e.a, h, mu, ground), length, kSameMaths * (1.0 + length) + dd);
    // the values scale with the integration length: relative uncertainty dd / length on top
    const double same = kSameMaths + (length > 0 ? dd / length : 0.0);
    double ray[3], mie[3], uvwz[4], tr[3], tm[3], ts[3];
    ref3::single_scattering(&e.a, T.data.data(), h, mu, mu_s, nu, ground, ray, mie);
    ref3::scattering_uvwz(&e.a, h, mu, mu_s, nu, ground, uvwz);
    const char* uv[4] = {"u_nu", "u_mu_s", "u_mu", "u_r"};
    // u_mu = 0.5 ± 0.5·coord((d − d_min)/(d_max − d_min)): d carries the tangent uncertainty
    const double rho = std::sqrt(r * r - e.m.bottom_radius_km * e.m.bottom_radius_km);
    const double u_mu_tol = 1e-12 + 0.5 * dd / std::max(rho - (r - e.m.bottom_radius_km), 1e-3);
    for (int k = 0; k < 4; ++k)
      EXPECT_NEAR(uvwz[k], row[csv.col(uv[k])], k == 2 ? u_mu_tol : 1e-12) << uv[k] << " r=" << r << " mu=" << mu;
    ref3::get_scattering(&e.a, SR.data.data(), h, mu, mu_s, nu, ground, tr);
    ref3::get_scattering(&e.a, SM.data.data(), h, mu, mu_s, nu, ground, tm);
    ref3::get_scattering(&e.a, S.data.data(), h, mu, mu_s, nu, ground, ts);
    for (int c = 0; c < 3; ++c) {
      EXPECT_LE(rel(ray[c], row[csv.col(std::string("rayleigh_") + ch[c])], 1e-300), same)
          << "r=" << r << " mu=" << mu << " mu_s=" << mu_s << " nu=" << nu;
      EXPECT_LE(rel(mie[c], row[csv.col(std::string("mie_") + ch[c])], 1e-300), same);
      // lookups: relative to the value, floored at 1e-7 of the texture's maximum (float32 storage)
      EXPECT_LE(rel(tr[c], row[csv.col(std::string("tex_single_rayleigh_") + ch[c])], 1e-7 * max_sr), kFloat32Storage);
      EXPECT_LE(rel(tm[c], row[csv.col(std::string("tex_single_mie_") + ch[c])], 1e-7 * max_sm), kFloat32Storage);
      EXPECT_LE(rel(ts[c], row[csv.col(std::string("tex_scattering_") + ch[c])], 1e-7 * max_s), kFloat32Storage);
    }
  }
}

TEST(AtmosphereReference, ScatteringTexelParameters) {
  Earth e;
  const auto csv = read_csv(ref("scattering_texel_params.csv"));
  ASSERT_EQ(csv.rows.size(), 500u);
  for (const auto& row : csv.rows) {
    const int i = static_cast<int>(row[csv.col("i")]), j = static_cast<int>(row[csv.col("j")]),
              k = static_cast<int>(row[csv.col("k")]);
    double h, mu, mu_s, nu;
    int ground;
    ref3::scattering_params_from_texel(&e.a, i, j, k, &h, &mu, &mu_s, &nu, &ground);
    const double r = e.m.bottom_radius_km + h;
    // float64 decode of the same formulas (ours avoid two cancellations): agreement to ~1e-12
    EXPECT_NEAR(r, row[csv.col("r_m")] * 1e-3, 1e-9) << i << "," << j << "," << k;
    EXPECT_NEAR(mu, row[csv.col("mu")], 1e-10) << i << "," << j << "," << k;
    EXPECT_NEAR(mu_s, row[csv.col("mu_s")], 1e-10) << i << "," << j << "," << k;
    // nu is clamped to mu·mu_s ± sqrt((1 − mu²)(1 − mu_s²)): near |mu| = 1 a change δ in mu moves
    // the bound by up to sqrt(2δ)
    EXPECT_NEAR(nu, row[csv.col("nu")], 1e-10 + 2.0 * std::sqrt(std::fabs(mu - row[csv.col("mu")]) + 1e-15))
        << i << "," << j << "," << k;
    EXPECT_EQ(ground, row[csv.col("ray_r_mu_intersects_ground")] != 0.0);
  }
}

// The sampling side: GetSkyRadiance from the reference's own textures reproduces its points.
TEST(AtmosphereReference, SkyRadianceFromReferenceTextures) {
  Earth e;
  Luts luts;
  luts.model = e.m;
  luts.rgb = e.ch;
  luts.transmittance = read_npy(ref("textures/transmittance.npy")).data;
  luts.irradiance = read_npy(ref("textures/irradiance.npy")).data;
  luts.scattering = read_npy(ref("textures/scattering.npy")).data;
  luts.single_mie = read_npy(ref("textures/single_mie_scattering.npy")).data;
  const Renderer render(luts);
  const auto csv = read_csv(ref("sky_radiance_points.csv"));
  ASSERT_EQ(csv.rows.size(), 60u);
  const char* ch[3] = {"R", "G", "B"};
  for (const auto& row : csv.rows) {
    const double alt = row[csv.col("camera_altitude_m")] * 1e-3, vmu = row[csv.col("view_mu")],
                 smu = row[csv.col("sun_mu")], az = row[csv.col("sun_azimuth_rad")];
    const Vec3 camera{0, 0, e.m.bottom_radius_km + alt};
    const Vec3 view{std::sqrt(1 - vmu * vmu), 0, vmu};
    const Vec3 sun{std::sqrt(1 - smu * smu) * std::cos(az), std::sqrt(1 - smu * smu) * std::sin(az), smu};
    Vec3 t{};
    const Vec3 l = render.sky_radiance(camera, view, sun, &t);
    for (int c = 0; c < 3; ++c) {
      const double want = row[csv.col(std::string("radiance_") + ch[c])];
      EXPECT_LE(rel(l[c], want, 1e-12), kFloat32Storage) << "alt=" << alt << " view_mu=" << vmu << " sun_mu=" << smu;
      EXPECT_LE(rel(t[c], row[csv.col(std::string("transmittance_") + ch[c])], 1e-300), kSameMaths);
    }
  }
}
