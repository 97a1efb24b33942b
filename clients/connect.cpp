#include "clients/connect.h"

#include "cli/text_file.h"

#include <stdexcept>

namespace palpate::client {

namespace {

// HOST of HOST:PORT (brackets of [v6] removed), or the whole when it has no port.
std::string host_of(const std::string& address) {
  std::string host = address;
  const auto colon = address.rfind(':');
  if (colon != std::string::npos && address.find(']') == std::string::npos && address.find(':') == colon)
    host = address.substr(0, colon);
  else if (address.size() > 0 && address[0] == '[')
    host = address.substr(1, address.find(']') - 1);
  return host;
}

capnp::ReaderOptions reader_options(uint64_t words) {
  capnp::ReaderOptions o;
  o.traversalLimitInWords = words;
  return o;
}

}  // namespace

std::string read_token_file(const std::string& file) {
  const std::string token = palpate::cli::trim_white_space(palpate::cli::read_text_file(file, "access token file"));
  if (token.empty()) throw std::invalid_argument("access token file " + file + ": it is empty");
  return token;
}

ServerConnection::ServerConnection(const ConnectOptions& options)
    : own_io_(kj::heap<kj::AsyncIoContext>(kj::setupAsyncIo())), io_(*own_io_), server_(nullptr) {
  connect(options);
}

ServerConnection::ServerConnection(const ConnectOptions& options, kj::AsyncIoContext& io)
    : io_(io), server_(nullptr) {
  connect(options);
}

void ServerConnection::connect(const ConnectOptions& options) {
  auto address = io_.provider->getNetwork().parseAddress(options.address, 7420).wait(io_.waitScope);
  stream_ = address->connect().wait(io_.waitScope);
  if (!options.tls_ca_file.empty()) {
    const std::string pem = palpate::cli::read_text_file(options.tls_ca_file, "TLS CA file");
    ca_ = kj::heap<kj::TlsCertificate>(kj::StringPtr(pem.c_str()));
    kj::TlsContext::Options tls_options;
    tls_options.trustedCertificates = kj::arrayPtr(ca_.get(), 1);
    tls_options.useSystemTrustStore = false;
    tls_ = kj::heap<kj::TlsContext>(kj::mv(tls_options));
    const std::string name = options.tls_server_name.empty() ? host_of(options.address) : options.tls_server_name;
    stream_ = tls_->wrapClient(kj::mv(stream_), name).wait(io_.waitScope);
  }
  network_ = kj::heap<capnp::TwoPartyVatNetwork>(*stream_, capnp::rpc::twoparty::Side::CLIENT,
                                                 reader_options(options.traversal_limit_words));
  rpc_ = kj::heap<capnp::RpcSystem<capnp::rpc::twoparty::VatId>>(capnp::makeRpcClient(*network_));
  capnp::word scratch[4] = {};
  capnp::MallocMessageBuilder message(scratch);
  auto server_id = message.getRoot<capnp::rpc::twoparty::VatId>();
  server_id.setSide(capnp::rpc::twoparty::Side::SERVER);
  server_ = rpc_->bootstrap(server_id).castAs<wire::PalpateServer>();
  if (!options.access_token.empty()) {
    auto req = server_.authenticateRequest();
    req.setAccessToken(options.access_token);
    server_ = req.send().wait(io_.waitScope).getServer();
  }
}

ServerConnection::~ServerConnection() = default;

}  // namespace palpate::client
