#include "kinds/diffraction/table.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/parallel.hpp"
#include "kinds/diffraction/reference.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

namespace {
constexpr double kPi = 3.141592653589793238462643;
constexpr double kTwoPi = 2.0 * kPi;

// Phasors e^{−2πi·f_k·x_j} for every frequency k and sample j of one axis: [k][j] as re, im.
void axis_phasors(const std::vector<double>& freqs, int samples, double dx, std::vector<double>& re,
                  std::vector<double>& im) {
  const std::size_t n = freqs.size();
  re.resize(n * samples);
  im.resize(n * samples);
  const double x0 = 0.5 * (samples - 1);
  for (std::size_t k = 0; k < n; ++k)
    for (int j = 0; j < samples; ++j) {
      // The phase reduced to [0, 1) cycles before the trigonometry keeps it exact to ~1e-16
      // whatever f·x is.
      double cyc = freqs[k] * (j - x0) * dx;
      cyc -= std::floor(cyc);
      re[k * samples + j] = std::cos(kTwoPi * cyc);
      im[k * samples + j] = -std::sin(kTwoPi * cyc);
    }
}

double percentile99(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::floor(0.99 * static_cast<double>(v.size() - 1)))];
}

// A fixed linear congruential sequence (Knuth's MMIX constants): the same points every run.
struct Lcg {
  std::uint64_t x = 0x9E3779B97F4A7C15ull;
  double next() {
    x = x * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(x >> 11) * (1.0 / 9007199254740992.0);
  }
};
}  // namespace

double disc_coherence_length_um(double theta_rad, double lambda_um) { return 2.0 * lambda_um / (kPi * theta_rad); }

double coherence_reference_lambda_um(const DiffractionSpec& spec) {
  return 0.5 * (spec.range_nm.lo + spec.range_nm.hi) * 1e-3;
}

double coherence_length_um(const DiffractionSpec& spec) {
  if (spec.coherence.length_um) return *spec.coherence.length_um;
  return disc_coherence_length_um(spec.coherence.source_angular_diameter_deg * kPi / 180.0,
                                  coherence_reference_lambda_um(spec));
}

double TableGeometry::freq_at_s(double sv) const {
  const double a = std::pow(std::fabs(sv), power) * f_max;
  return sv < 0 ? -a : a;
}

double TableGeometry::width(int i) const {
  const double sv = std::fabs(s(i));
  return power * (power == 1.0 ? 1.0 : std::pow(sv, power - 1.0)) * f_max * 2.0 / size;
}

double TableGeometry::texel_of(double f) const {
  const double a = std::pow(std::fabs(f) / f_max, 1.0 / power);
  const double sv = f < 0 ? -a : a;
  return (sv + 1.0) * size / 2.0 - 0.5;
}

TableGeometry table_geometry(const DiffractionSpec& spec, int size) {
  TableGeometry g;
  g.size = size;
  g.power = spec.table ? spec.table->power : 1.0;
  g.f_max = spec.table && spec.table->f_max_per_um ? *spec.table->f_max_per_um : 2.0 / (spec.range_nm.lo * 1e-3);
  return g;
}

Window make_window(const Field& f, double sigma_um) {
  Window w;
  w.sigma_um = sigma_um;
  auto axis = [&](int m, std::vector<double>& out) {
    out.resize(m);
    const double x0 = 0.5 * (m - 1);
    for (int j = 0; j < m; ++j) {
      const double x = (j - x0) * f.dx_um;
      out[j] = std::exp(-x * x / (2.0 * sigma_um * sigma_um));
    }
  };
  axis(f.width, w.wx);
  axis(f.height, w.wy);
  double sx = 0, sy = 0, qx = 0, qy = 0;
  for (double v : w.wx) sx += v, qx += v * v;
  for (double v : w.wy) sy += v, qy += v * v;
  w.sum = sx * sy;
  w.sum_sq = qx * qy;
  return w;
}

std::vector<cplx> table_terms(const Field& f, const Window& w, const std::vector<Band>& bands, const TableGeometry& g) {
  const int n = g.size, W = f.width, H = f.height;
  std::vector<double> freqs(n);
  for (int i = 0; i < n; ++i) freqs[i] = g.freq(i);
  std::vector<double> eur, eui, evr, evi;
  axis_phasors(freqs, W, f.dx_um, eur, eui);
  axis_phasors(freqs, H, f.dx_um, evr, evi);
  int total = 0;
  for (const auto& b : bands) total = std::max(total, b.first_term + b.terms);
  const std::size_t per = static_cast<std::size_t>(n) * n;
  std::vector<cplx> out(per * total);
  const double inv = 1.0 / (static_cast<double>(W) * H);
  std::vector<double> ar(static_cast<std::size_t>(W) * H), ai(ar.size());
  std::vector<double> gr(static_cast<std::size_t>(H) * n), gi(gr.size());
  for (const auto& band : bands)
    for (int t = 0; t < band.terms; ++t) {
      const auto q = reference_inputs(f, band, t, 1);
      for (int iy = 0; iy < H; ++iy)
        for (int ix = 0; ix < W; ++ix) {
          const std::size_t j = static_cast<std::size_t>(iy) * W + ix;
          const double wj = w.wx[ix] * w.wy[iy];
          ar[j] = wj * q[j].real();
          ai[j] = wj * q[j].imag();
        }
      // Rows: G[iy][iu] = Σ_ix a[iy][ix]·e^{−2πi f_u x}.
      parallel_for(H, [&](long long iy) {
        const double* rr = ar.data() + iy * W;
        const double* ri = ai.data() + iy * W;
        for (int iu = 0; iu < n; ++iu) {
          const double* er = eur.data() + static_cast<std::size_t>(iu) * W;
          const double* ei = eui.data() + static_cast<std::size_t>(iu) * W;
          double sr = 0, si = 0;
          for (int ix = 0; ix < W; ++ix) {
            sr += rr[ix] * er[ix] - ri[ix] * ei[ix];
            si += rr[ix] * ei[ix] + ri[ix] * er[ix];
          }
          gr[iy * n + iu] = sr;
          gi[iy * n + iu] = si;
        }
      });
      // Columns: F[iv][iu] = Σ_iy e^{−2πi f_v y}·G[iy][iu].
      cplx* dst = out.data() + per * (band.first_term + t);
      parallel_for(n, [&](long long iv) {
        std::vector<double> sr(n, 0.0), si(n, 0.0);
        for (int iy = 0; iy < H; ++iy) {
          const double er = evr[iv * H + iy], ei = evi[iv * H + iy];
          const double* pr = gr.data() + static_cast<std::size_t>(iy) * n;
          const double* pi = gi.data() + static_cast<std::size_t>(iy) * n;
          for (int iu = 0; iu < n; ++iu) {
            sr[iu] += er * pr[iu] - ei * pi[iu];
            si[iu] += er * pi[iu] + ei * pr[iu];
          }
        }
        for (int iu = 0; iu < n; ++iu) dst[iv * n + iu] = {sr[iu] * inv, si[iu] * inv};
      });
    }
  return out;
}

std::vector<cplx> windowed_field(const Field& f, const Window& w, double kappa) {
  std::vector<cplx> a(static_cast<std::size_t>(f.count()));
  for (int iy = 0; iy < f.height; ++iy)
    for (int ix = 0; ix < f.width; ++ix) {
      const std::size_t j = static_cast<std::size_t>(iy) * f.width + ix;
      a[j] = w.wx[ix] * w.wy[iy] * std::polar(1.0, kappa * f.h_um[j]);
    }
  return a;
}

cplx direct_transform(const std::vector<cplx>& a, const Field& f, double fu, double fv) {
  const double x0 = 0.5 * (f.width - 1), y0 = 0.5 * (f.height - 1);
  double sr = 0, si = 0;
  for (int iy = 0; iy < f.height; ++iy)
    for (int ix = 0; ix < f.width; ++ix) {
      // The full 2D phase per sample, reduced to [0, 1) cycles.
      double cyc = (fu * (ix - x0) + fv * (iy - y0)) * f.dx_um;
      cyc -= std::floor(cyc);
      const double c = std::cos(kTwoPi * cyc), s = -std::sin(kTwoPi * cyc);
      const cplx v = a[static_cast<std::size_t>(iy) * f.width + ix];
      sr += v.real() * c - v.imag() * s;
      si += v.real() * s + v.imag() * c;
    }
  return {sr, si};
}

cplx table_value(const std::vector<float>& terms, const TableGeometry& g, const Field& f, const Band& band,
                 double kappa, int iu, int iv) {
  std::vector<double> coef(band.terms);
  ref::expansion_coefficients(band.expansion == Expansion::taylor ? 0 : 1, kappa, band.kappa0, band.delta, f.s,
                              band.terms, coef.data());
  const std::size_t per = static_cast<std::size_t>(g.size) * g.size, at = static_cast<std::size_t>(iv) * g.size + iu;
  double sr = 0, si = 0;
  for (int t = 0; t < band.terms; ++t) {
    const std::size_t i = 2 * ((band.first_term + t) * per + at);
    sr += coef[t] * terms[i];
    si += coef[t] * terms[i + 1];
  }
  return static_cast<double>(f.count()) * std::polar(1.0, kappa * f.c) * cplx(sr, si);
}

cplx table_bilinear(const std::vector<float>& terms, const TableGeometry& g, const Field& f, const Band& band,
                    double kappa, double tu, double tv) {
  const double cu = std::clamp(tu, 0.0, g.size - 1.0), cv = std::clamp(tv, 0.0, g.size - 1.0);
  const int u0 = std::min(static_cast<int>(std::floor(cu)), g.size - 2), v0 = std::min(static_cast<int>(std::floor(cv)), g.size - 2);
  const double a = cu - u0, b = cv - v0;
  return (1 - a) * (1 - b) * table_value(terms, g, f, band, kappa, u0, v0) +
         a * (1 - b) * table_value(terms, g, f, band, kappa, u0 + 1, v0) +
         (1 - a) * b * table_value(terms, g, f, band, kappa, u0, v0 + 1) +
         a * b * table_value(terms, g, f, band, kappa, u0 + 1, v0 + 1);
}

nlohmann::json TableError::json() const {
  return {{"at_texels", {{"max_over_window_sum", texel_max}, {"p99_over_window_sum", texel_p99},
                         {"at_kappa", texel_at_kappa}, {"points_per_kappa", texel_points},
                         {"per_kappa", texel_per_kappa}}},
          {"between_texels_bilinear", {{"max_over_window_sum", between_max}, {"p99_over_window_sum", between_p99},
                                       {"at_kappa", between_at_kappa}, {"points_per_kappa", between_points},
                                       {"per_kappa", between_per_kappa}}},
          {"kappas", kappas},
          {"energy_ratio_per_kappa", energy_ratio},
          {"reference", "direct double-precision sum over the samples of w * exp(i kappa h) * exp(-2 pi i f.x)"}};
}

TableError measure_table(const Field& f, const Window& w, const std::vector<Band>& bands, const TableGeometry& g,
                         const std::vector<float>& terms, const std::vector<double>& kappas) {
  const int n = g.size;
  // Points per κ: as many as keep the direct sums near 1.5e8 sample visits per κ (32–256 of each kind).
  const int budget = static_cast<int>(std::clamp(1.5e8 / static_cast<double>(f.count()), 32.0, 256.0));
  // Texel centres: the 4×4 around the centre (the specular peak), the corners, then a fixed
  // pseudo-random sample.
  std::vector<std::pair<double, double>> texels, between;
  for (int dv = -2; dv < 2; ++dv)
    for (int du = -2; du < 2; ++du) texels.emplace_back(n / 2 + du, n / 2 + dv);
  for (auto [u, v] : std::vector<std::pair<int, int>>{{0, 0}, {n - 1, 0}, {0, n - 1}, {n - 1, n - 1}})
    texels.emplace_back(u, v);
  Lcg rng;
  while (static_cast<int>(texels.size()) < budget)
    texels.emplace_back(std::floor(rng.next() * n), std::floor(rng.next() * n));
  // Between texels: the 8×8 cell centres around the peak, then fixed pseudo-random positions.
  for (int dv = -4; dv < 4; ++dv)
    for (int du = -4; du < 4; ++du) between.emplace_back(n / 2 + du - 0.5 + 1.0, n / 2 + dv - 0.5 + 1.0);
  while (static_cast<int>(between.size()) < budget)
    between.emplace_back(rng.next() * (n - 1), rng.next() * (n - 1));

  auto freq_of = [&](double t) { return g.freq_at_s(2.0 * (t + 0.5) / n - 1.0); };
  TableError e;
  e.kappas = kappas;
  e.texel_points = static_cast<int>(texels.size());
  e.between_points = static_cast<int>(between.size());
  std::vector<double> all_t, all_b;
  const double inv = 1.0 / w.sum;
  for (double kappa : kappas) {
    const Band& band = band_for(bands, kappa);
    const auto a = windowed_field(f, w, kappa);
    std::vector<double> et(texels.size()), eb(between.size());
    parallel_for(static_cast<long long>(texels.size() + between.size()), [&](long long i) {
      if (i < static_cast<long long>(texels.size())) {
        const auto [tu, tv] = texels[i];
        const cplx ex = direct_transform(a, f, freq_of(tu), freq_of(tv));
        et[i] = std::abs(table_value(terms, g, f, band, kappa, static_cast<int>(tu), static_cast<int>(tv)) - ex) * inv;
      } else {
        const auto [tu, tv] = between[i - texels.size()];
        const cplx ex = direct_transform(a, f, freq_of(tu), freq_of(tv));
        eb[i - texels.size()] = std::abs(table_bilinear(terms, g, f, band, kappa, tu, tv) - ex) * inv;
      }
    });
    const double mt = *std::max_element(et.begin(), et.end()), mb = *std::max_element(eb.begin(), eb.end());
    e.texel_per_kappa.push_back(mt);
    e.between_per_kappa.push_back(mb);
    if (mt >= e.texel_max) e.texel_max = mt, e.texel_at_kappa = kappa;
    if (mb >= e.between_max) e.between_max = mb, e.between_at_kappa = kappa;
    all_t.insert(all_t.end(), et.begin(), et.end());
    all_b.insert(all_b.end(), eb.begin(), eb.end());
    // Parseval: Σ|P|²·(texel area) over the table against ∫∫|P|² df over a period = Σw²/dx².
    std::vector<double> rows(n);
    parallel_for(n, [&](long long iv) {
      double s = 0;
      for (int iu = 0; iu < n; ++iu) s += std::norm(table_value(terms, g, f, band, kappa, iu, iv)) * g.width(iu);
      rows[iv] = s * g.width(static_cast<int>(iv));
    });
    double energy = 0;
    for (double r : rows) energy += r;
    e.energy_ratio.push_back(energy / (w.sum_sq / (f.dx_um * f.dx_um)));
  }
  e.texel_p99 = percentile99(all_t);
  e.between_p99 = percentile99(all_b);
  return e;
}

}  // namespace specbake::diffraction
