#pragma once
// A message_filters stage between a subscriber and the synchronizer: passes on the messages of one input that
// pass their check and hands the others, with the reason, to a callback that counts and reports them. Without
// it a malformed message that never forms a synchronized set (its partner messages are fine, or missing) would be
// dropped by the synchronizer with no count and no word.
#include <message_filters/simple_filter.h>

#include <exception>
#include <functional>
#include <string>

namespace diffdope_ros {

template <class M>
class CheckedInput : public message_filters::SimpleFilter<M> {
 public:
  using Check = std::function<void(const M&)>;                      // throws std::exception with the reason
  using Reject = std::function<void(const std::string& reason)>;
  using Arrive = std::function<void(const M&)>;                     // every message, before its check

  template <class Upstream>
  void connect(Upstream& upstream, Arrive arrive, Check check, Reject reject) {
    arrive_ = std::move(arrive), check_ = std::move(check), reject_ = std::move(reject);
    connection_ = upstream.registerCallback(
        boost::function<void(const boost::shared_ptr<M const>&)>([this](const boost::shared_ptr<M const>& m) {
          on_message(m);
        }));
  }
  void disconnect() { connection_.disconnect(); }

 private:
  void on_message(const boost::shared_ptr<M const>& m) {
    if (arrive_) arrive_(*m);
    try {
      if (check_) check_(*m);
    } catch (const std::exception& e) {
      if (reject_) reject_(e.what());
      return;
    }
    this->signalMessage(m);
  }

  Arrive arrive_;
  Check check_;
  Reject reject_;
  message_filters::Connection connection_;
};

}  // namespace diffdope_ros
