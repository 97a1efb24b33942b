#pragma once
// Shared by the server request fuzzer and its seed generator: the input format.
//
//   byte 0       which request the rest carries (Kind)
//   bytes 1...   one Cap'n Proto message in the standard flat framing
//                (segment table + segments, capnp::messageToFlatArray)
#include <cstdint>

namespace palpate::fuzz {

enum Kind : uint8_t {
  open_request = 0,  // wire::OpenRequest -> PalpateServer.openSession
  set_force = 1,     // wire::Session::SetForceParams -> Session.setForce
  step = 2,          // wire::Session::StepParams -> Session.step
  subscribe = 3,     // wire::Session::SubscribeParams -> Session.subscribe
  set_position = 4,  // wire::Session::SetPositionParams -> Session.setPosition
  set_force_vector = 5,  // wire::Session::SetForceVectorParams -> Session.setForceVector
  set_coupling = 6,  // wire::Session::SetCouplingParams -> Session.setCoupling
  kind_count = 7,
};

}  // namespace palpate::fuzz
