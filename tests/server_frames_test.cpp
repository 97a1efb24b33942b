// The Frame filled from a published Snapshot (server/frames.h): in a multirate session each
// frame is one render tick's, on the newest step's body (docs/protocol.md, "Multirate").
#include <gtest/gtest.h>

#include <capnp/message.h>

#include "server/frames.h"

namespace palpate::server {
namespace {

// A render made from an older step than the newest one, which has applied a setPosition the
// render does not include: the frame says what its force includes, not what the step applied.
TEST(Frames, AMultirateFrameNamesTheCommandItsForceIncludes) {
  Snapshot step;
  step.tick = 12;
  step.command_seq = 7;  // the setPosition, applied by this step
  step.position_mode = true;
  step.target = Vec3(0, 0, 0.55);
  HapticSample render;
  render.haptic_tick = 40;
  render.model_tick = 11;
  render.command_seq = 6;  // rendered from the step before it, in force mode
  render.target = Vec3(0, 0, 0.457);
  render.render_force = Vec3(0, 0, 0.1);
  const std::vector<uint32_t> no_surface;

  capnp::MallocMessageBuilder rendered;
  fill_frame(rendered.initRoot<wire::Frame>(), step, FieldRequest{}, nullptr, no_surface, &render);
  const auto f = rendered.getRoot<wire::Frame>().asReader();
  EXPECT_EQ(f.getCommandSeq(), 6u);
  EXPECT_EQ(f.getTarget().getZ(), 0.457);
  EXPECT_EQ(f.getRenderForce().getZ(), 0.1);
  EXPECT_EQ(f.getHapticTick(), 40);
  EXPECT_EQ(f.getTick(), 12);  // on the newest step's body

  // A render of a setPosition newer than its step names that command.
  render.command_seq = 8;
  render.target = Vec3(0, 0, 0.6);
  capnp::MallocMessageBuilder ahead;
  fill_frame(ahead.initRoot<wire::Frame>(), step, FieldRequest{}, nullptr, no_surface, &render);
  EXPECT_EQ(ahead.getRoot<wire::Frame>().asReader().getCommandSeq(), 8u);

  // Without multirate the frame is the step's own.
  capnp::MallocMessageBuilder own;
  fill_frame(own.initRoot<wire::Frame>(), step, FieldRequest{}, nullptr, no_surface);
  const auto g = own.getRoot<wire::Frame>().asReader();
  EXPECT_EQ(g.getCommandSeq(), 7u);
  EXPECT_EQ(g.getTarget().getZ(), 0.55);
  EXPECT_EQ(g.getHapticTick(), -1);
}

}  // namespace
}  // namespace palpate::server
