#include "core/rate_schedule.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "core/force_blocks.h"
#include "core/model.h"
#include "core/time_step.h"

namespace palpate {

namespace {

// s with its lowest `bits` bits in reverse order.
int bit_reverse(int s, int bits) {
  int r = 0;
  for (int b = 0; b < bits; ++b) r |= ((s >> b) & 1) << (bits - 1 - b);
  return r;
}

// Gershgorin's bound of row i of M^-1/2 K M^-1/2 at rest (1.20), for every free particle
// (0 for fixed ones): sum_j ||K_ij|| / sqrt(m_i m_j) with ||K_ij|| bounded by the support
// domains holding both, sum_b v_b (lambda_b + 2 mu_b + k_v) |d_bi| |d_bj|, and hourglass
// control's springs kappa_b w_bj between b and its neighbours.
std::vector<double> gershgorin_bounds(const Model& m) {
  const int n = m.particle_count;
  std::vector<double> scale(n), g(n, 0.0);  // scale: 1 / sqrt(m_i), 0 for a fixed particle
  for (int i = 0; i < n; ++i) scale[i] = m.fixed[i] ? 0.0 : 1.0 / std::sqrt(m.mass[i]);
  for (int b = 0; b < n; ++b) {
    const int begin = m.neighbor_offset[b], end = m.neighbor_offset[b + 1];
    Vec3 self = Vec3::Zero();  // d_bb = -sum_j d_bj
    double sum = 0.0;          // S_b = sum over the domain's members of |d_bj| / sqrt(m_j)
    for (int a = begin; a < end; ++a) {
      self -= m.gradient_weight.col(a);
      sum += m.gradient_weight.col(a).norm() * scale[m.neighbor_index[a]];
    }
    sum += self.norm() * scale[b];
    const double c = m.volume[b] * (m.particle_lambda[b] + 2 * m.particle_mu[b] + m.volume_stiffness);
    for (int a = begin; a < end; ++a) {
      const int j = m.neighbor_index[a];
      g[j] += c * m.gradient_weight.col(a).norm() * sum * scale[j];
    }
    g[b] += c * self.norm() * sum * scale[b];
    if (m.hourglass_weight.empty()) continue;
    for (int a = begin; a < end; ++a) {
      const int j = m.neighbor_index[a];
      const double k = m.hourglass_weight[a];
      g[b] += k * scale[b] * (scale[b] + scale[j]);
      g[j] += k * scale[j] * (scale[j] + scale[b]);
    }
  }
  return g;
}

}  // namespace

void build_rate_schedule(Model& m, int max_interval, double dt, double safety) {
  if (max_interval < 1 || max_interval > 64 || (max_interval & (max_interval - 1)) != 0)
    throw std::invalid_argument("the longest update interval must be a power of two in 1 ... 64, got " +
                                std::to_string(max_interval));
  if (!(safety > 0.0)) throw std::invalid_argument("the subcycling safety factor must be positive");
  if (!(dt > 0.0)) throw std::invalid_argument("the subcycled step must be positive");
  assert(m.solid == SolidKind::mls && !m.blocks.empty() && "subcycling needs the MLS blocked layout");
  const int n = m.particle_count;
  RateSchedule& s = m.rate_schedule;
  s = RateSchedule{};
  s.period = max_interval;
  s.dt = dt;
  s.interval.assign(n, 1);
  s.phase.assign(n, 0);
  // Intervals: the largest power of two within safety times the particle's own stable step (1.20).
  const std::vector<double> g = gershgorin_bounds(m);
  const double g_max = *std::max_element(g.begin(), g.end());
  const double stable = m.spectral_time_step > 0 ? m.spectral_time_step : stable_time_step(m, IntegratorType::symplectic_euler);
  for (int i = 0; i < n; ++i) {
    if (m.fixed[i] || g[i] <= 0.0) continue;
    const double ratio = safety * stable / dt * std::sqrt(g_max / g[i]);
    int k = 1;
    while (2 * k <= max_interval && 2 * k <= ratio) k *= 2;
    s.interval[i] = static_cast<uint8_t>(k);
  }
  // Phases: by angle about the finest class's centre, sectors in bit-reversed order.
  double cx = 0, cy = 0;
  int fine = 0;
  for (int i = 0; i < n; ++i)
    if (!m.fixed[i] && s.interval[i] == 1) {
      cx += m.rest_position(0, i);
      cy += m.rest_position(1, i);
      ++fine;
    }
  if (fine > 0) cx /= fine, cy /= fine;
  // One set of sectors for all classes, of equal coarse work (1 / k_i a particle) each, so that
  // a class's sectors are unions of the next finer class's and their phases nest: phase
  // bitreverse(s) mod k_i in sector s.
  std::vector<int> coarse;
  for (int i = 0; i < n; ++i)
    if (!m.fixed[i] && s.interval[i] > 1) coarse.push_back(i);
  std::vector<double> angle(n);
  for (int i : coarse) angle[i] = std::atan2(m.rest_position(1, i) - cy, m.rest_position(0, i) - cx);
  std::stable_sort(coarse.begin(), coarse.end(), [&](int a, int b) { return angle[a] < angle[b]; });
  double coarse_work = 0;
  for (int i : coarse) coarse_work += 1.0 / s.interval[i];
  int bits = 0;
  while ((1 << bits) < max_interval) ++bits;
  double so_far = 0;
  for (int i : coarse) {
    const int sector = std::min(max_interval - 1, static_cast<int>(max_interval * (so_far + 0.5 / s.interval[i]) / coarse_work));
    so_far += 1.0 / s.interval[i];
    s.phase[i] = static_cast<uint8_t>(bit_reverse(sector, bits) & (s.interval[i] - 1));
  }
  // The ticks each free particle updates at, as bits of the period's phases.
  std::vector<uint64_t> ticks(n, 0);
  for (int i = 0; i < n; ++i) {
    if (m.fixed[i]) continue;
    for (int p = s.phase[i]; p < s.period; p += s.interval[i]) ticks[i] |= uint64_t{1} << p;
  }
  // The domain of particle c (c and its neighbours) is evaluated at every tick one of its
  // members updates at; the blocks are regrouped so that domains of the same ticks share a
  // block (ties in particle order), and a block is evaluated at its four domains' ticks.
  std::vector<uint64_t> domain_ticks(n, 0);
  for (int c = 0; c < n; ++c) {
    domain_ticks[c] = ticks[c];
    for (int a = m.neighbor_offset[c]; a < m.neighbor_offset[c + 1]; ++a) domain_ticks[c] |= ticks[m.neighbor_index[a]];
  }
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return domain_ticks[a] < domain_ticks[b]; });
  build_force_blocks(m, order);
  const int blocks = static_cast<int>(m.blocks.size());
  std::vector<uint64_t>& block_ticks = s.block_ticks;
  block_ticks.assign(blocks, 0);
  std::vector<std::vector<int>> holding(n);  // the blocks whose domains hold each particle
  std::vector<int> listed(n, -1);
  for (int b = 0; b < blocks; ++b) {
    auto add = [&](int j) {
      if (listed[j] != b) holding[j].push_back(b), listed[j] = b;
    };
    for (int l = 0; l < m.blocks[b].lanes; ++l) {
      const int c = m.blocks[b].particle[l];
      block_ticks[b] |= domain_ticks[c];
      add(c);
      for (int a = m.neighbor_offset[c]; a < m.neighbor_offset[c + 1]; ++a) add(m.neighbor_index[a]);
    }
  }
  s.particle_block_offset.assign(1, 0);
  for (int i = 0; i < n; ++i) {
    s.particle_block_index.insert(s.particle_block_index.end(), holding[i].begin(), holding[i].end());
    s.particle_block_offset.push_back(static_cast<int>(s.particle_block_index.size()));
  }
  s.block_offset.assign(1, 0);
  s.slots_at_phase.assign(s.period, 0);
  for (int b = 0; b < blocks; ++b) s.slots_total += m.blocks[b].slot_end - m.blocks[b].slot_begin;
  for (int p = 0; p < s.period; ++p) {
    for (int b = 0; b < blocks; ++b)
      if (block_ticks[b] >> p & 1) {
        s.block_index.push_back(b);
        s.slots_at_phase[p] += m.blocks[b].slot_end - m.blocks[b].slot_begin;
      }
    s.block_offset.push_back(static_cast<int>(s.block_index.size()));
  }
}

}  // namespace palpate
