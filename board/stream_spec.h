// The text form of a live stream's destination, as written on the command line
// (`caphub run --stream`) and in a board file's [outputs] streams: KIND:HOST:PORT[@RATE].
#pragma once

#include <string>
#include <string_view>

#include "board/board.h"
#include "hal/core/error.h"

namespace caphub::board {

// "vmc", "vrchat", "caphub".
std::string_view streamKindName(StreamKind kind);
// The port a kind's receivers listen on by default (VMC 39539, VRChat 9000, caphub 39600).
int defaultStreamPort(StreamKind kind);

// Parses KIND[:HOST[:PORT]][@RATE]: HOST defaults to 127.0.0.1, PORT to the kind's default,
// RATE (Hz, 1-1000) to 60. An IPv6 address is written in brackets ("[::1]"). The error says
// what was expected (EINVAL).
Result<StreamConfig> parseStreamSpec(std::string_view spec);
// The spec back as text, every part written out.
std::string toString(const StreamConfig& s);

}  // namespace caphub::board
