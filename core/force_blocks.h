#pragma once
// The blocked layout of the MLS force loops (Model::blocks, Model::block_slots and, with
// hourglass control, their terms): the support domains, gradient weights, rest corrections,
// volumes and Lame parameters regrouped four particles at a time, neighbour lists padded to
// the block's longest (core/mls_loops.h reads them).
#include <vector>

#include "core/model.h"

namespace palpate {

// (Re)builds the blocks of an MLS model whose support domains, weights and volumes are set:
// block b holds the particles order[4b .. 4b+3] (order: a permutation of the particles; empty:
// particle order), the last block's missing lanes padding that repeat its last particle.
void build_force_blocks(Model& m, const std::vector<int>& order = {});

}  // namespace palpate
