// The report of a haptic client run as text and as JSON fields (clients/haptic.h).
#include "clients/haptic.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace palpate::haptic {

namespace {

std::string number(double x) {
  if (!std::isfinite(x)) return "null";
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", x);
  return b;
}

double percent(double x, double peak) { return peak > 0 ? 100.0 * x / peak : NAN; }

void print_error_row(std::FILE* out, const char* name, const RenderingError::Report& e, double peak) {
  std::fprintf(out, "  %-12s %6zu   %9.3g %9.3g %9.3g (%6.2f %%)   %9.3g %9.3g %9.3g (%6.2f %%)\n", name, e.local.count,
               e.local.p50, e.local.p99, e.local.max, percent(e.local.p99, peak), e.hold.p50, e.hold.p99, e.hold.max,
               percent(e.hold.p99, peak));
}

std::string json_percentiles(const std::string& prefix, const Percentiles& p, double peak) {
  return "\"" + prefix + "_p50_n\": " + number(p.p50) + ", \"" + prefix + "_p99_n\": " + number(p.p99) + ", \"" +
         prefix + "_max_n\": " + number(p.max) + ", \"" + prefix + "_p50_pct\": " + number(percent(p.p50, peak)) +
         ", \"" + prefix + "_p99_pct\": " + number(percent(p.p99, peak)) + ", \"" + prefix +
         "_max_pct\": " + number(percent(p.max, peak));
}

}  // namespace

void print_report(std::FILE* out, const Result& r) {
  const ServerStats& s = r.server;
  std::fprintf(out, "command->force    p50 %.3f ms, p99 %.3f ms, max %.3f ms (%zu of %zu setPosition matched)\n",
               r.latency_ms.p50, r.latency_ms.p99, r.latency_ms.max, r.latency_ms.count, r.commands);
  std::fprintf(out, "server            %.1f Hz achieved (target %.0f Hz), step p50 %.0f us, p99 %.0f us\n",
               s.achieved_hz, s.target_hz, s.step_p50_us, s.step_p99_us);
  std::fprintf(out, "tick lateness     p50 %.0f us, p99 %.0f us, max %.0f us; deadline misses %llu of %lld ticks, "
               "%llu skipped, blow-ups %u%s\n",
               s.lateness_p50_us, s.lateness_p99_us, s.lateness_max_us,
               static_cast<unsigned long long>(s.deadline_misses), static_cast<long long>(s.ticks),
               static_cast<unsigned long long>(s.skipped_ticks), s.blow_ups, s.realtime_priority ? ", SCHED_FIFO" : "");
  if (s.refocuses > 0 || s.refocuses_dropped > 0)
    std::fprintf(out, "refocus           %llu swapped in, %llu dropped (the cloud follows the tool)\n",
                 static_cast<unsigned long long>(s.refocuses), static_cast<unsigned long long>(s.refocuses_dropped));
  if (s.haptic_rate_hz > 0) {
    std::fprintf(out, "multirate         render ticks at %.0f Hz: %lld, misses %llu, lateness p99 %.0f us; model age "
                 "p50 %.2f ms, p99 %.2f ms, max %.2f ms (frames received: p50 %.2f ms, p99 %.2f ms)\n",
                 s.haptic_rate_hz, static_cast<long long>(s.haptic_ticks),
                 static_cast<unsigned long long>(s.haptic_misses), s.haptic_lateness_p99_us, 1e-3 * s.model_age_p50_us,
                 1e-3 * s.model_age_p99_us, 1e-3 * s.model_age_max_us, r.model_age_ms.p50, r.model_age_ms.p99);
  }
  std::fprintf(out, "contact stiffness age p50 %.0f, p99 %.0f, max %.0f ticks behind its frame (%.1f / %.1f / %.1f ms); "
               "touching: p50 %.0f, p99 %.0f ticks; %zu frames touching before the first\n",
               r.stiffness_age_ticks.p50, r.stiffness_age_ticks.p99, r.stiffness_age_ticks.max,
               1e3 * r.stiffness_age_ticks.p50 / s.target_hz, 1e3 * r.stiffness_age_ticks.p99 / s.target_hz,
               1e3 * r.stiffness_age_ticks.max / s.target_hz, r.stiffness_age_touching_ticks.p50,
               r.stiffness_age_touching_ticks.p99, r.touching_without_stiffness);
  std::fprintf(out, "misses in frames  %llu reported by the stream as they happened (Frame.deadlineMisses)\n",
               static_cast<unsigned long long>(r.misses_seen_in_frames));
  std::fprintf(out, "frames            %zu received, %llu dropped by the server, %zu compared, %zu gaps\n", r.frames,
               static_cast<unsigned long long>(s.frames_dropped), r.compared, r.gaps);
  std::fprintf(out, "servo loop        %zu ticks, %zu skipped, wake-up lateness p99 %.0f us%s\n", r.servo_ticks,
               r.servo_skipped, r.servo_wake_p99_us, r.client_fifo ? ", SCHED_FIFO" : "");
  std::fprintf(out, "rendering error   |F_next - prediction|, N (peak |F| %.4g N): local model vs zero-order hold\n",
               r.peak_force);
  std::fprintf(out, "  %-12s %6s   %9s %9s %9s %10s   %9s %9s %9s %10s\n", "segment", "frames", "local p50", "p99",
               "max", "(p99/peak)", "hold p50", "p99", "max", "(p99/peak)");
  for (size_t k = 0; k < r.segments.size() && k < r.error_per_segment.size(); ++k)
    print_error_row(out, r.segments[k].label.c_str(), r.error_per_segment[k], r.peak_force);
  print_error_row(out, "all", r.error, r.peak_force);
  print_error_row(out, "late ticks", r.error_late, r.peak_force);
  std::fflush(out);
}

std::string json_fields(const Result& r) {
  const ServerStats& s = r.server;
  std::string j = "\"latency_p50_ms\": " + number(r.latency_ms.p50) + ", \"latency_p99_ms\": " +
                  number(r.latency_ms.p99) + ", \"latency_max_ms\": " + number(r.latency_ms.max) +
                  ", \"commands\": " + std::to_string(r.commands) + ", \"commands_matched\": " +
                  std::to_string(r.latency_ms.count) + ", \"achieved_rate_hz\": " + number(s.achieved_hz) +
                  ", \"target_rate_hz\": " + number(s.target_hz) + ", \"ticks\": " + std::to_string(s.ticks) +
                  ", \"step_p50_us\": " + number(s.step_p50_us) + ", \"step_p99_us\": " + number(s.step_p99_us) +
                  ", \"lateness_p50_us\": " + number(s.lateness_p50_us) + ", \"lateness_p99_us\": " +
                  number(s.lateness_p99_us) + ", \"lateness_max_us\": " + number(s.lateness_max_us) +
                  ", \"deadline_misses\": " + std::to_string(s.deadline_misses) + ", \"skipped_ticks\": " +
                  std::to_string(s.skipped_ticks) + ", \"blow_ups\": " + std::to_string(s.blow_ups) +
                  ", \"realtime_priority\": " + (s.realtime_priority ? "true" : "false") +
                  ", \"refocuses\": " + std::to_string(s.refocuses) +
                  ", \"refocuses_dropped\": " + std::to_string(s.refocuses_dropped) +
                  ", \"haptic_rate_hz\": " + number(s.haptic_rate_hz) + ", \"haptic_ticks\": " +
                  std::to_string(s.haptic_ticks) + ", \"haptic_misses\": " + std::to_string(s.haptic_misses) +
                  ", \"haptic_lateness_p99_us\": " + number(s.haptic_lateness_p99_us) +
                  ", \"model_age_p50_us\": " + number(s.model_age_p50_us) + ", \"model_age_p99_us\": " +
                  number(s.model_age_p99_us) + ", \"model_age_max_us\": " + number(s.model_age_max_us) +
                  ", \"misses_seen_in_frames\": " + std::to_string(r.misses_seen_in_frames) +
                  ", \"stiffness_age_ticks_p50\": " + number(r.stiffness_age_ticks.p50) +
                  ", \"stiffness_age_ticks_p99\": " + number(r.stiffness_age_ticks.p99) +
                  ", \"stiffness_age_touching_ticks_p50\": " + number(r.stiffness_age_touching_ticks.p50) +
                  ", \"stiffness_age_touching_ticks_p99\": " + number(r.stiffness_age_touching_ticks.p99) +
                  ", \"touching_without_stiffness\": " + std::to_string(r.touching_without_stiffness) +
                  ", \"frames\": " + std::to_string(r.frames) + ", \"frames_dropped\": " +
                  std::to_string(s.frames_dropped) + ", \"frames_compared\": " + std::to_string(r.compared) +
                  ", \"frame_gaps\": " + std::to_string(r.gaps) + ", \"servo_ticks\": " +
                  std::to_string(r.servo_ticks) + ", \"servo_skipped\": " + std::to_string(r.servo_skipped) +
                  ", \"servo_wake_p99_us\": " + number(r.servo_wake_p99_us) +
                  ", \"client_fifo\": " + (r.client_fifo ? "true" : "false") + ", \"peak_force_n\": " +
                  number(r.peak_force) + ", \"error\": {" + json_percentiles("local", r.error.local, r.peak_force) +
                  ", " + json_percentiles("hold", r.error.hold, r.peak_force) + "}, \"error_late_ticks\": {" +
                  "\"frames\": " + std::to_string(r.error_late.local.count) + ", " +
                  json_percentiles("local", r.error_late.local, r.peak_force) + ", " +
                  json_percentiles("hold", r.error_late.hold, r.peak_force) + "}, \"segments\": [";
  for (size_t k = 0; k < r.segments.size() && k < r.error_per_segment.size(); ++k) {
    const auto& e = r.error_per_segment[k];
    j += std::string(k ? ", " : "") + "{\"segment\": \"" + r.segments[k].label + "\", \"motion\": \"" +
         motion_name(r.segments[k].motion) + "\", \"t0_s\": " + number(r.segments[k].t0) + ", \"t1_s\": " +
         number(r.segments[k].t1) + ", \"frames\": " + std::to_string(e.local.count) + ", " +
         json_percentiles("local", e.local, r.peak_force) + ", " + json_percentiles("hold", e.hold, r.peak_force) +
         "}";
  }
  return j + "]";
}

}  // namespace palpate::haptic
