// A client's sessions as hapco-report lists them (io/recording_sessions.h), on step sequences
// written by hand: the cases of single servers, moves, and the overloaded-host patterns.
#include "io/recording_sessions.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace hapco::io {
namespace {

struct Row {
  const char* server;
  std::uint64_t step;
  bool force_only = false;
};

std::vector<RecordedSession> SessionsOf(const std::vector<Row>& rows) {
  ClientSessions sessions;
  for (const Row& row : rows) {
    recording::Step step;
    step.set_server_id(row.server);
    step.set_step(row.step);
    step.set_contacts_missing(row.force_only);
    sessions.Add(step);
  }
  return sessions.sessions();
}

std::string Listing(const std::vector<RecordedSession>& sessions) {
  std::string out;
  for (const auto& s : sessions) {
    out += (out.empty() ? "" : ", ") + std::to_string(s.first_step) + ".." + std::to_string(s.last_step) + " on " +
           s.server_id + " (" + std::to_string(s.steps) + ", " + std::to_string(s.missing) + " missing)";
  }
  return out;
}

// A recorder started 1.7 s into a session has its steps from 1712 on: the 1711 before are
// not in the file (the recorder counted them missing; the report said 0 not in the file).
TEST(RecordingSessions, StepsBeforeASessionsFirstRecordedOneAreCounted) {
  const std::vector<RecordedSession> late = SessionsOf({{"a", 1712}, {"a", 1713}, {"b", 1}, {"b", 2}, {"c", 5}});
  ASSERT_EQ(late.size(), 3u) << Listing(late);
  EXPECT_EQ(late[0].before_first(), 1711u);
  EXPECT_EQ(late[1].before_first(), 0u);
  EXPECT_EQ(late[2].before_first(), 4u);
}

TEST(RecordingSessions, OneServerWithAGapIsOneSession) {
  EXPECT_EQ(Listing(SessionsOf({{"a", 1}, {"a", 2}, {"a", 5}, {"a", 6}})), "1..6 on a (4, 2 missing)");
}

// Where the missing steps are: the longest run inside a session, by its first step.
TEST(RecordingSessions, TheLongestGapIsNamedByItsFirstStep) {
  const auto sessions = SessionsOf({{"a", 1}, {"a", 2}, {"a", 5}, {"a", 6}, {"a", 20}, {"a", 21}, {"a", 23}});
  ASSERT_EQ(sessions.size(), 1u);
  EXPECT_EQ(sessions[0].missing, 2u + 13u + 1u);
  EXPECT_EQ(sessions[0].largest_gap, 13u);        // 7..19
  EXPECT_EQ(sessions[0].largest_gap_first, 7u);
  const auto whole = SessionsOf({{"a", 1}, {"a", 2}, {"a", 3}});
  EXPECT_EQ(whole[0].largest_gap, 0u);
}

TEST(RecordingSessions, ACounterStartingAgainOrAnotherServerStartsASession) {
  // Restart on a, move to b, back to a (a's counter from 1 again).
  EXPECT_EQ(Listing(SessionsOf({{"a", 1}, {"a", 2}, {"a", 1}, {"b", 1}, {"b", 2}, {"a", 1}})),
            "1..2 on a (2, 0 missing), 1..1 on a (1, 0 missing), 1..2 on b (2, 0 missing), 1..1 on a (1, 0 missing)");
}

// The compose run's pattern: after a move from a to b, poses sent to a before the move arrive
// there late and a steps them, interleaved with b's new session. Before, each switch was a
// new "session" (33 for one client in 8 s).
TEST(RecordingSessions, AnotherServersStepsInBetweenDoNotEndASession) {
  EXPECT_EQ(Listing(SessionsOf({{"a", 1342}, {"b", 1}, {"a", 1343}, {"b", 2}, {"b", 3}, {"a", 1348}, {"b", 4}})),
            "1342..1348 on a (3, 4 missing), 1..4 on b (4, 0 missing)");
}

// Steps written from forces whose frames were lost carry the lowest possible number, and
// several can share one ("1628..1628" nine times in a compose run): the same session.
TEST(RecordingSessions, ForceOnlyStepsWithARepeatedNumberStayInTheirSession) {
  std::vector<Row> rows = {{"a", 1627}, {"a", 1628}};
  for (int k = 0; k < 9; ++k) rows.push_back({"a", 1628, true});
  rows.push_back({"a", 1629});
  EXPECT_EQ(Listing(SessionsOf(rows)), "1627..1629 on a (12, 0 missing)");
  // The frame of a step already written from its force (it came late): the same session.
  rows.push_back({"a", 1630, true});
  rows.push_back({"a", 1630});
  EXPECT_EQ(Listing(SessionsOf(rows)), "1627..1630 on a (14, 0 missing)");
  // A frame's step (contacts present) below the last one is a new session, as before.
  rows.push_back({"a", 1});
  EXPECT_EQ(SessionsOf(rows).size(), 2u);
}

}  // namespace
}  // namespace hapco::io
