#pragma once
// Multirate haptics (docs/protocol.md, "Multirate"): the full model steps at the
// session's rate on the session's loop, while this renderer, a thread of its own at
// the haptic rate, evaluates the newest step's render model (Frame.renderModel, the
// rendered force as a function of the device position, docs/protocol.md (P.1)) at the
// newest device position (setPosition) and publishes a small sample per render tick.
// The RPC thread streams a frame per sample: the sample's force and target on the
// newest step's body and tool. This is how a model too slow for 1 kHz (the graded
// and tetrahedral clouds) serves a device that needs a force every millisecond.
//
// Threads: offer_model() from the session's loop only; offer_device() and samples()
// from the RPC thread only; counters() from any thread.
#include <atomic>
#include <cstdint>
#include <thread>

#include "core/types.h"
#include "server/deadlines.h"
#include "server/histogram.h"
#include "server/snapshot.h"

namespace palpate::server {

// What a step hands the renderer (at each publish).
struct RenderInput {
  bool valid = false;          // false: no step published yet
  LocalModel render_model;     // Snapshot::render_model
  Vec3 render_force{0, 0, 0};  // the step's own render force, saturated (force mode renders it as it is)
  bool force_saturated = false;  // the step saturated it
  Vec3 target{0, 0, 0};        // the device position the step used, m
  bool position_mode = false;
  int64_t tick = 0;            // the step's tick
  int64_t publish_ns = 0;      // when the step was published
  uint64_t command_seq = 0;    // the last command the step applied
};

// What a step's frame hands the renderer.
RenderInput render_input_of(const Snapshot& step);

// The newest setPosition.
struct DeviceInput {
  Vec3 target{0, 0, 0};  // m
  uint64_t seq = 0;      // its command sequence number (0: none yet)
};

// One render tick's result.
struct HapticSample {
  int64_t haptic_tick = 0;
  int64_t publish_ns = 0;      // when it was rendered
  Vec3 target{0, 0, 0};        // the device position rendered at, m
  Vec3 render_force{0, 0, 0};  // N
  bool force_saturated = false;
  int64_t model_tick = 0;          // the step rendered from
  int64_t model_publish_ns = 0;
  uint64_t command_seq = 0;        // the newest command this force includes
  uint64_t haptic_misses = 0;      // render ticks missed so far
};

// Scales f to max_force (> 0; 0 = no limit) when it is longer; true if it did.
bool saturate(Vec3& f, double max_force);

// One render tick without the thread: the sample for the newest step and device input
// (the renderer's tick; the multirate verification, palpate-bench-multirate, calls it
// directly). Position mode renders the step's render model at the device position
// (the step's own target before any setPosition reached the renderer), saturated at
// max_force; force mode the step's render force (already saturated by the step).
HapticSample render_sample(const RenderInput& model, const DeviceInput& device, double max_force);

struct HapticCounters {
  int64_t ticks = 0;
  uint64_t misses = 0, watchdog_rests = 0;
  Histogram::Summary lateness_us, model_age_us;
};

class HapticRenderer {
 public:
  // Starts the thread: SCHED_FIFO one above the loop's priority when `try_realtime`
  // and allowed, ticking at rate_hz; each sample is published and signalled by
  // writing 1 to wake_fd (the session's eventfd).
  // rpc_heartbeat: given way to as the session's loop does (SimConfig::rpc_heartbeat).
  HapticRenderer(double rate_hz, double max_force, double spin_margin_us, bool try_realtime, int wake_fd,
                 const RpcHeartbeat* rpc_heartbeat = nullptr);
  ~HapticRenderer();  // stops and joins
  HapticRenderer(const HapticRenderer&) = delete;
  HapticRenderer& operator=(const HapticRenderer&) = delete;

  void offer_model(const RenderInput& input);                // the session's loop
  void offer_device(const Vec3& target, uint64_t seq);       // RPC thread
  TripleBuffer<HapticSample>::Reader& samples() { return samples_reader_; }  // RPC thread
  HapticCounters counters() const;                           // any thread
  double rate_hz() const { return rate_hz_; }

 private:
  void run();

  const double rate_hz_, max_force_, spin_margin_us_;
  const bool try_realtime_;
  const int wake_fd_;
  const RpcHeartbeat* const rpc_heartbeat_;
  TripleBuffer<RenderInput>::Writer model_writer_;    // the session's loop
  TripleBuffer<RenderInput>::Reader model_reader_;    // renderer thread
  TripleBuffer<DeviceInput>::Writer device_writer_;   // RPC thread
  TripleBuffer<DeviceInput>::Reader device_reader_;   // renderer thread
  TripleBuffer<HapticSample>::Writer samples_writer_; // renderer thread
  TripleBuffer<HapticSample>::Reader samples_reader_; // RPC thread
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> ticks_{0};
  std::atomic<uint64_t> misses_{0}, watchdog_rests_{0};
  Histogram lateness_us_, model_age_us_;
  std::thread thread_;  // last: started when everything above exists
};

}  // namespace palpate::server
