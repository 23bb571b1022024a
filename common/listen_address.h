// What a server's listen address ("HOST:PORT") means for its start-up: why
// it cannot be bound (so that the refusal names the cause), and whether it
// reaches beyond this machine (so that an open default can be refused).
//
//   if (!started.ok()) ... DescribeListenFailure("127.0.0.1:7002")
//     // "address already in use (another process is listening on it)"
//   IsLoopbackAddress("0.0.0.0:7002")  // false
#ifndef TPR_COMMON_LISTEN_ADDRESS_H_
#define TPR_COMMON_LISTEN_ADDRESS_H_

#include <string>

namespace tpr::common {

// DescribeListenFailure says why `address` ("HOST:PORT", "[V6]:PORT") cannot
// be listened on, by trying to bind it once without SO_REUSEPORT:
// "address already in use (another process is listening on it)", the
// resolver's or bind's error, or "bind failed" when the trial bind
// succeeds (the failure was elsewhere). Cost: one resolution and one bind.
std::string DescribeListenFailure(const std::string& address);

// IsLoopbackAddress reports whether every address `address` ("HOST:PORT")
// listens on is on this machine only: a host of 127.0.0.0/8, ::1,
// "localhost", or a "unix:" socket path. Wildcards (0.0.0.0, [::], an empty
// host) and every other host are beyond loopback.
bool IsLoopbackAddress(const std::string& address);

}  // namespace tpr::common

#endif  // TPR_COMMON_LISTEN_ADDRESS_H_
