#pragma once
// Opening a hertz_cube session in an end-to-end test, over either transport.
#include <string>
#include <vector>

#include <kj/async.h>
#include <kj/exception.h>

#include "protocol/palpate.capnp.h"

namespace palpate::test {

// The error message of a failing call, or "" if it succeeded.
template <class Request>
std::string error_of(Request&& req, kj::WaitScope& ws) {
  try {
    req.send().wait(ws);
  } catch (const kj::Exception& e) {
    return e.getDescription().cStr();
  }
  return "";
}

// hertz_cube with overrides ("key=value"); rate_hz 0 is the server's rate.
inline wire::Session::Client open_session(wire::PalpateServer::Client& server, kj::WaitScope& ws, bool headless,
                                          const std::vector<std::string>& overrides = {"body.distribution.per_edge=8"},
                                          double rate_hz = 0.0) {
  auto req = server.openSessionRequest();
  auto r = req.initRequest();
  r.getScene().setName("hertz_cube");
  auto o = r.initOverrides(static_cast<unsigned>(overrides.size()));
  for (unsigned k = 0; k < overrides.size(); ++k) o.set(k, overrides[k]);
  r.setHeadless(headless);
  r.setRateHz(rate_hz);
  return req.send().wait(ws).getSession();
}

}  // namespace palpate::test
