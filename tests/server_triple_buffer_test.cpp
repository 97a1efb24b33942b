// The triple buffer between a session's thread and the RPC thread (server/snapshot.h):
// the reader gets the newest published frame, never an older one than it already
// has, and never one the writer is still filling.
#include <array>
#include <atomic>
#include <cstdint>
#include <thread>
#include <type_traits>
#include <vector>

#include <gtest/gtest.h>

#include "server/snapshot.h"

namespace palpate::server {
namespace {

// A frame whose every word carries its sequence number: a torn frame (written while
// read) has words of two frames.
struct Frame {
  uint64_t seq = 0;
  std::array<uint64_t, 512> words{};
  void fill(uint64_t s) {
    seq = s;
    words.fill(s);
  }
  bool whole() const {
    for (uint64_t w : words)
      if (w != seq) return false;
    return true;
  }
};

using Buffer = TripleBuffer<Frame>;

static_assert(!std::is_copy_constructible_v<Buffer::Writer> && !std::is_copy_assignable_v<Buffer::Writer>);
static_assert(!std::is_copy_constructible_v<Buffer::Reader> && !std::is_copy_assignable_v<Buffer::Reader>);
static_assert(std::is_nothrow_move_constructible_v<Buffer::Writer> && std::is_nothrow_move_constructible_v<Buffer::Reader>);

TEST(TripleBuffer, NothingToTakeBeforeTheFirstPublish) {
  Buffer b;
  EXPECT_FALSE(b.reader.take());
  EXPECT_EQ(b.reader.front().seq, 0u);  // value-initialised
  EXPECT_TRUE(b.reader.front().whole());
}

TEST(TripleBuffer, EveryFrameIsTakenOnceWhenTheReaderKeepsUp) {
  Buffer b;
  for (uint64_t s = 1; s <= 10; ++s) {
    b.writer.back().fill(s);
    EXPECT_FALSE(b.writer.publish()) << "frame " << s - 1 << " was taken, nothing was replaced";
    ASSERT_TRUE(b.reader.take());
    EXPECT_EQ(b.reader.front().seq, s);
    EXPECT_TRUE(b.reader.front().whole());
    EXPECT_FALSE(b.reader.take()) << "the same frame twice";
    EXPECT_EQ(b.reader.front().seq, s);  // front() stays until the next take()
  }
}

TEST(TripleBuffer, TheNewestFrameWins) {
  Buffer b;
  b.writer.back().fill(1);
  EXPECT_FALSE(b.writer.publish());
  b.writer.back().fill(2);
  EXPECT_TRUE(b.writer.publish()) << "frame 1 was never taken: replaced";
  b.writer.back().fill(3);
  EXPECT_TRUE(b.writer.publish());
  ASSERT_TRUE(b.reader.take());
  EXPECT_EQ(b.reader.front().seq, 3u);
  EXPECT_TRUE(b.reader.front().whole());
  EXPECT_FALSE(b.reader.take());
}

TEST(TripleBuffer, TheWriterNeverFillsTheReadersFrame) {
  Buffer b;
  b.writer.back().fill(1);
  b.writer.publish();
  ASSERT_TRUE(b.reader.take());
  const Frame* held = &b.reader.front();
  // However often the writer publishes without the reader taking, the frame the
  // reader holds is never handed to the writer.
  for (uint64_t s = 2; s < 50; ++s) {
    ASSERT_NE(&b.writer.back(), held) << "at frame " << s;
    b.writer.back().fill(s);
    b.writer.publish();
    EXPECT_EQ(held->seq, 1u);
    EXPECT_TRUE(held->whole());
  }
  ASSERT_TRUE(b.reader.take());
  EXPECT_EQ(b.reader.front().seq, 49u);
}

TEST(TripleBuffer, PrepareRunsOncePerSlot) {
  int calls = 0;
  TripleBuffer<std::vector<float>> b([&calls](std::vector<float>& v) {
    v.reserve(1000);
    ++calls;
  });
  EXPECT_EQ(calls, 3);
  // Every slot the writer gets keeps its capacity: filling never allocates.
  for (int k = 0; k < 6; ++k) {
    EXPECT_GE(b.writer.back().capacity(), 1000u);
    b.writer.back().assign(1000, static_cast<float>(k));
    b.writer.publish();
    if (k % 2) b.reader.take();
  }
}

TEST(TripleBuffer, HandlesMoveWithTheirEnd) {
  Buffer b;
  Buffer::Writer writer = std::move(b.writer);
  Buffer::Reader reader = std::move(b.reader);
  writer.back().fill(7);
  writer.publish();
  ASSERT_TRUE(reader.take());
  EXPECT_EQ(reader.front().seq, 7u);
}

// A writer thread publishing sequence-numbered frames as fast as it can, a reader
// thread taking as fast as it can: the reader's frames only get newer, each is whole,
// and the last one it sees is the last one published. Halfway the writer waits until the
// reader has taken a frame, so the two really overlap however the threads are scheduled
// (on a loaded machine the writer could otherwise finish before the reader starts).
TEST(TripleBuffer, TwoThreadsNeverSeeAnOlderOrATornFrame) {
  constexpr uint64_t kFrames = 200000;
  Buffer b;
  std::atomic<bool> done{false};
  std::atomic<uint64_t> taken_so_far{0};
  uint64_t replaced = 0;
  std::thread writer([&] {
    for (uint64_t s = 1; s <= kFrames; ++s) {
      if (s == kFrames / 2)
        while (taken_so_far.load(std::memory_order_acquire) == 0) std::this_thread::yield();
      b.writer.back().fill(s);
      if (b.writer.publish()) ++replaced;
    }
    done.store(true, std::memory_order_release);
  });
  uint64_t last = 0, taken = 0, torn = 0, older = 0;
  for (;;) {
    const bool finished = done.load(std::memory_order_acquire);  // then this pass sees every frame
    while (b.reader.take()) {
      const Frame& f = b.reader.front();
      ++taken;
      taken_so_far.store(taken, std::memory_order_release);
      if (!f.whole()) ++torn;
      if (f.seq <= last) ++older;
      last = f.seq;
    }
    if (finished) break;
  }
  writer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(older, 0u);
  EXPECT_EQ(last, kFrames) << "the newest frame is always there to take";
  EXPECT_GT(taken, 1u);
  EXPECT_EQ(taken + replaced, kFrames) << "each frame was either taken or replaced by a newer one";
}

}  // namespace
}  // namespace palpate::server
