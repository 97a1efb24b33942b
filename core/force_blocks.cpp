#include "core/force_blocks.h"

#include <algorithm>
#include <cassert>

namespace palpate {

void build_force_blocks(Model& m, const std::vector<int>& order) {
  constexpr int W = Model::block_width;
  const int n = m.particle_count;
  assert(order.empty() || order.size() == static_cast<size_t>(n));
  auto particle = [&](int k) { return order.empty() ? k : order[k]; };  // the k-th lane's particle
  const int block_count = (n + W - 1) / W;
  m.blocks.assign(block_count, Model::ParticleBlock{});
  m.block_slots.clear();
  for (int b = 0; b < block_count; ++b) {
    Model::ParticleBlock& block = m.blocks[b];
    int longest = 0;
    block.lanes = std::min(W, n - W * b);
    for (int l = 0; l < W; ++l) {
      // A padding lane repeats the block's last particle (its weights are zero).
      block.particle[l] = particle(W * b + std::min(l, block.lanes - 1));
      if (l < block.lanes) longest = std::max(longest, m.neighbor_offset[block.particle[l] + 1] - m.neighbor_offset[block.particle[l]]);
    }
    block.slot_begin = static_cast<int>(m.block_slots.size());
    block.slot_end = block.slot_begin + longest;
    m.block_slots.resize(block.slot_end, Model::NeighborSlot{});
    for (int l = 0; l < W; ++l) {
      const int i = block.particle[l];
      if (l >= block.lanes) {  // padding lane: weightless, its neighbours are particle 0, F = I (stress free, and
                     // no law meets a singular F there: the vectorised polar decomposition needs det F > 0)
        block.volume[l] = 0.0;
        block.lame_lambda[l] = m.lame_lambda;
        block.lame_mu[l] = m.lame_mu;
        for (int k = 0; k < 9; ++k) block.rest_correction[k][l] = (k % 4 == 0) ? 1.0 : 0.0;
        for (int c = 0; c < 3; ++c) block.self_weight[c][l] = 0.0;
        continue;
      }
      block.volume[l] = m.volume[i];
      block.lame_lambda[l] = m.particle_lambda[i];
      block.lame_mu[l] = m.particle_mu[i];
      for (int k = 0; k < 9; ++k) block.rest_correction[k][l] = m.rest_correction[9 * static_cast<size_t>(i) + k];
      const int count = m.neighbor_offset[i + 1] - m.neighbor_offset[i];
      for (int s = 0; s < longest; ++s) {
        Model::NeighborSlot& slot = m.block_slots[block.slot_begin + s];
        const int a = m.neighbor_offset[i] + s;
        slot.j[l] = s < count ? m.neighbor_index[a] : i;
        for (int c = 0; c < 3; ++c) slot.d[c][l] = s < count ? m.gradient_weight(c, a) : 0.0;
      }
      for (int c = 0; c < 3; ++c) {
        double sum = 0;
        for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) sum += m.gradient_weight(c, a);
        block.self_weight[c][l] = -sum;
      }
    }
  }
  if (m.hourglass_weight.empty()) {
    m.block_hourglass_slots.clear();
    m.block_hourglass.clear();
    return;
  }
  // Hourglass control's blocked terms (docs/physics.md (1.9a)); zero in padding slots and lanes.
  m.block_hourglass_slots.assign(m.block_slots.size(), Model::HourglassSlot{});
  m.block_hourglass.assign(block_count, Model::HourglassBlock{});
  for (int b = 0; b < block_count; ++b) {
    const Model::ParticleBlock& block = m.blocks[b];
    Model::HourglassBlock& hg = m.block_hourglass[b];
    for (int l = 0; l < block.lanes; ++l) {
      const int i = block.particle[l];
      Mat3 H = Mat3::Zero();
      Vec3 e_sum = Vec3::Zero();
      for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
        const double k = m.hourglass_weight[a];
        const Vec3 X_ij = m.neighbor_rest_offset.col(a);
        H += k * X_ij * X_ij.transpose();
        e_sum += k * X_ij;
        Model::HourglassSlot& slot = m.block_hourglass_slots[block.slot_begin + (a - m.neighbor_offset[i])];
        slot.k[l] = k;
        for (int c = 0; c < 3; ++c) slot.e[c][l] = k * X_ij[c];
        hg.active = hg.active || k != 0;
      }
      const int entry[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};
      for (int q = 0; q < 6; ++q) hg.H[q][l] = H(entry[q][0], entry[q][1]);
      for (int c = 0; c < 3; ++c) hg.e_sum[c][l] = e_sum[c];
    }
  }
}

}  // namespace palpate
