#include "board/sim/bvh.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <utility>

#include <fmt/format.h>

#include "hal/core/input_file.h"

namespace caphub::board::sim {

namespace {

constexpr int kMaxChannelsPerJoint = 6;

bool isSpace(char c) {
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

char lower(char c) {
    return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c;
}

bool equalsNoCase(std::string_view a, std::string_view b) {
    if (a.size() != b.size()) {
        return false;
    }
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (lower(a[i]) != lower(b[i])) {
            return false;
        }
    }
    return true;
}

// A token as it appears in an error message: quoted, cut short, non-printable bytes escaped,
// because fuzzed or binary input must still give a readable message.
std::string quote(std::string_view token) {
    constexpr std::size_t kMax = 40;
    std::string out = "'";
    for (std::size_t i = 0; i < token.size() && i < kMax; ++i) {
        const auto c = static_cast<unsigned char>(token[i]);
        if (c >= 0x20 && c < 0x7f) {
            out += static_cast<char>(c);
        } else {
            out += fmt::format("\\x{:02x}", c);
        }
    }
    if (token.size() > kMax) {
        out += "...";
    }
    out += "'";
    return out;
}

struct Token {
    std::string_view text;  // empty at end of input
    int line = 0;
    bool end() const { return text.empty(); }
};

// Splits the text into whitespace-separated tokens, with '{' and '}' always tokens of their own,
// and counts lines.
class Scanner {
public:
    explicit Scanner(std::string_view text) : text_(text) {}

    // At the end of the input the token is empty and carries the line of the last token, the
    // line a person looks at to see what is missing.
    Token peek() {
        skipSpace();
        const std::string_view t = tokenAt(pos_);
        return Token{t, t.empty() ? lastLine_ : line_};
    }

    Token next() {
        Token t = peek();
        pos_ += t.text.size();
        if (!t.end()) {
            lastLine_ = t.line;
        }
        return t;
    }

    // The line of the next token (or of the end of input).
    int line() {
        skipSpace();
        return line_;
    }

    // True when the next token starts on the current line, i.e. no line break before it.
    bool nextOnSameLine() {
        std::size_t p = pos_;
        while (p < text_.size() && isSpace(text_[p])) {
            if (text_[p] == '\n') {
                return false;
            }
            ++p;
        }
        return p < text_.size();
    }

    // Consumes a literal word case-insensitively, allowing whitespace before it but nothing
    // glued to its end but ':' or whitespace. Used for "Frames:" and "Frame Time:", which
    // writers lay out in every possible way.
    bool consumeWord(std::string_view word) {
        skipSpace();
        if (text_.size() - pos_ < word.size() ||
            !equalsNoCase(text_.substr(pos_, word.size()), word)) {
            return false;
        }
        const std::size_t after = pos_ + word.size();
        if (after < text_.size() && !isSpace(text_[after]) && text_[after] != ':') {
            return false;
        }
        pos_ = after;
        lastLine_ = line_;
        return true;
    }

    bool consumeChar(char c) {
        skipSpace();
        if (pos_ < text_.size() && text_[pos_] == c) {
            ++pos_;
            lastLine_ = line_;
            return true;
        }
        return false;
    }

    std::size_t remaining() const { return text_.size() - pos_; }

private:
    void skipSpace() {
        while (pos_ < text_.size() && isSpace(text_[pos_])) {
            if (text_[pos_] == '\n') {
                ++line_;
            }
            ++pos_;
        }
    }

    std::string_view tokenAt(std::size_t p) const {
        if (p >= text_.size()) {
            return {};
        }
        if (text_[p] == '{' || text_[p] == '}') {
            return text_.substr(p, 1);
        }
        std::size_t e = p;
        while (e < text_.size() && !isSpace(text_[e]) && text_[e] != '{' && text_[e] != '}') {
            ++e;
        }
        return text_.substr(p, e - p);
    }

    std::string_view text_;
    std::size_t pos_ = 0;
    int line_ = 1;
    int lastLine_ = 1;
};

std::optional<BvhChannel> parseChannel(std::string_view s) {
    static constexpr std::array<std::pair<std::string_view, BvhChannel>, 6> kNames = {{
        {"Xposition", BvhChannel::Xposition},
        {"Yposition", BvhChannel::Yposition},
        {"Zposition", BvhChannel::Zposition},
        {"Xrotation", BvhChannel::Xrotation},
        {"Yrotation", BvhChannel::Yrotation},
        {"Zrotation", BvhChannel::Zrotation},
    }};
    for (const auto& [name, c] : kNames) {
        if (equalsNoCase(s, name)) {
            return c;
        }
    }
    return std::nullopt;
}

// A finite decimal number occupying the whole token. from_chars does not take a leading '+'.
std::optional<double> parseNumber(std::string_view s) {
    if (s.size() > 1 && s[0] == '+' && s[1] != '-') {
        s.remove_prefix(1);
    }
    double v = 0;
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || ptr != s.data() + s.size() || !std::isfinite(v)) {
        return std::nullopt;
    }
    return v;
}

std::optional<long long> parseInteger(std::string_view s) {
    if (s.size() > 1 && s[0] == '+') {
        s.remove_prefix(1);
    }
    long long v = 0;
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || ptr != s.data() + s.size()) {
        return std::nullopt;
    }
    return v;
}

class Parser {
public:
    Parser(std::string_view text, std::string_view sourceName) : scan_(text), source_(sourceName) {}

    Result<BvhClip> run() {
        if (!expectKeyword("HIERARCHY", "'HIERARCHY' at the start of the file")) {
            return takeError();
        }
        if (!parseHierarchy() || !parseMotion()) {
            return takeError();
        }
        return std::move(clip_);
    }

private:
    // Records the first error; always returns false so callers can `return fail(...)`.
    bool fail(int line, std::string_view expected, std::string_view found) {
        if (!error_) {
            error_ = Error{EINVAL, fmt::format("{}: line {}: expected {}, found {}", source_, line,
                                               expected, found)};
        }
        return false;
    }

    bool failAt(const Token& t, std::string_view expected) {
        return fail(t.line, expected, t.end() ? std::string("end of file") : quote(t.text));
    }

    Error takeError() { return error_ ? *error_ : Error{EINVAL, "internal parser error"}; }

    bool expectKeyword(std::string_view keyword, std::string_view expected) {
        const Token t = scan_.next();
        if (!equalsNoCase(t.text, keyword)) {
            return failAt(t, expected);
        }
        return true;
    }

    bool readNumber(std::string_view what, double& out) {
        const Token t = scan_.next();
        const auto v = parseNumber(t.text);
        if (!v) {
            return failAt(t, what);
        }
        out = *v;
        return true;
    }

    bool readVector(std::string_view keyword, Vec3d& out) {
        for (int i = 0; i < 3; ++i) {
            if (!readNumber(fmt::format("three numbers after {}", keyword), out[i])) {
                return false;
            }
        }
        return true;
    }

    // A joint name: every token on the rest of the keyword's line up to '{', joined by single
    // spaces (names with spaces exist in the wild); or, when the line ends right after the
    // keyword, the next token.
    bool readName(std::string_view keyword, std::string& out) {
        const Token first = scan_.peek();
        if (first.end() || first.text == "{" || first.text == "}") {
            return failAt(first, fmt::format("a joint name after {}", keyword));
        }
        out = std::string(scan_.next().text);
        while (scan_.nextOnSameLine()) {
            const Token t = scan_.peek();
            if (t.text == "{" || t.text == "}") {
                break;
            }
            out += ' ';
            out += scan_.next().text;
        }
        return true;
    }

    bool parseHierarchy() {
        // Joints whose body is open, innermost last: the parser is iterative so that deeply
        // nested input cannot exhaust the stack.
        std::vector<int> open;
        Token t = scan_.peek();
        if (!equalsNoCase(t.text, "ROOT")) {
            return failAt(t, "'ROOT' after HIERARCHY");
        }
        while (true) {
            t = scan_.next();
            if (open.empty()) {
                if (equalsNoCase(t.text, "ROOT")) {
                    if (!beginJoint("ROOT", t.line, -1, open)) {
                        return false;
                    }
                    continue;
                }
                if (equalsNoCase(t.text, "MOTION")) {
                    return true;
                }
                return failAt(t, "'ROOT' or 'MOTION' after a joint hierarchy");
            }
            const int j = open.back();
            BvhJoint& joint = clip_.joints[static_cast<std::size_t>(j)];
            if (equalsNoCase(t.text, "OFFSET")) {
                if (sawOffset_[static_cast<std::size_t>(j)]) {
                    return failAt(t, fmt::format("one OFFSET in joint '{}'", joint.name));
                }
                sawOffset_[static_cast<std::size_t>(j)] = true;
                if (!readVector("OFFSET", joint.offset)) {
                    return false;
                }
            } else if (equalsNoCase(t.text, "CHANNELS")) {
                if (sawChannels_[static_cast<std::size_t>(j)]) {
                    return failAt(t, fmt::format("one CHANNELS in joint '{}'", joint.name));
                }
                sawChannels_[static_cast<std::size_t>(j)] = true;
                if (!readChannels(j)) {
                    return false;
                }
            } else if (equalsNoCase(t.text, "JOINT")) {
                if (!requireOffset(j, t) || !beginJoint("JOINT", t.line, j, open)) {
                    return false;
                }
            } else if (equalsNoCase(t.text, "End")) {
                if (!requireOffset(j, t) || !readEndSite(j)) {
                    return false;
                }
            } else if (t.text == "}") {
                if (!requireOffset(j, t)) {
                    return false;
                }
                open.pop_back();
            } else {
                return failAt(t, fmt::format("OFFSET, CHANNELS, JOINT, End Site or '}}' in joint "
                                             "'{}' (declared on line {})",
                                             joint.name, joint.line));
            }
        }
    }

    bool requireOffset(int j, const Token& t) {
        if (!sawOffset_[static_cast<std::size_t>(j)]) {
            const BvhJoint& joint = clip_.joints[static_cast<std::size_t>(j)];
            return failAt(t, fmt::format("OFFSET in joint '{}' before its children and its '}}'",
                                         joint.name));
        }
        return true;
    }

    bool beginJoint(std::string_view keyword, int line, int parent, std::vector<int>& open) {
        BvhJoint joint;
        joint.parent = parent;
        joint.line = line;
        if (!readName(keyword, joint.name)) {
            return false;
        }
        const Token brace = scan_.next();
        if (brace.text != "{") {
            return failAt(brace, fmt::format("'{{' after {} {}", keyword, joint.name));
        }
        clip_.joints.push_back(std::move(joint));
        sawOffset_.push_back(false);
        sawChannels_.push_back(false);
        open.push_back(static_cast<int>(clip_.joints.size()) - 1);
        return true;
    }

    bool readChannels(int j) {
        BvhJoint& joint = clip_.joints[static_cast<std::size_t>(j)];
        const Token countToken = scan_.next();
        const auto count = parseInteger(countToken.text);
        if (!count || *count < 0 || *count > kMaxChannelsPerJoint) {
            return failAt(countToken, "a channel count from 0 to 6 after CHANNELS");
        }
        joint.firstChannel = clip_.channelCount;
        for (long long i = 0; i < *count; ++i) {
            const Token t = scan_.next();
            const auto c = parseChannel(t.text);
            if (!c) {
                return failAt(t, fmt::format("channel {} of {} of joint '{}' (Xposition, "
                                             "Yposition, Zposition, Xrotation, Yrotation or "
                                             "Zrotation)",
                                             i + 1, *count, joint.name));
            }
            for (BvhChannel seen : joint.channels) {
                if (seen == *c) {
                    return failAt(
                        t, fmt::format("each channel at most once in joint '{}'", joint.name));
                }
            }
            joint.channels.push_back(*c);
        }
        clip_.channelCount += static_cast<int>(*count);
        return true;
    }

    bool readEndSite(int j) {
        BvhJoint& joint = clip_.joints[static_cast<std::size_t>(j)];
        if (!expectKeyword("Site", "'Site' after 'End'")) {
            return false;
        }
        if (joint.endSite) {
            return fail(scan_.line(), fmt::format("one End Site in joint '{}'", joint.name),
                        "a second one");
        }
        if (!expectKeyword("{", "'{' after End Site") ||
            !expectKeyword("OFFSET", "OFFSET in End Site")) {
            return false;
        }
        Vec3d offset;
        if (!readVector("OFFSET", offset) || !expectKeyword("}", "'}' closing End Site")) {
            return false;
        }
        joint.endSite = offset;
        return true;
    }

    bool parseMotion() {
        if (!scan_.consumeWord("Frames") || !scan_.consumeChar(':')) {
            return failAt(scan_.peek(), "'Frames:' after MOTION");
        }
        const Token framesToken = scan_.next();
        const auto frames = parseInteger(framesToken.text);
        if (!frames || *frames < 0 || *frames > std::numeric_limits<int>::max()) {
            return failAt(framesToken, "a frame count (a whole number >= 0) after 'Frames:'");
        }
        if (!scan_.consumeWord("Frame") || !scan_.consumeWord("Time") || !scan_.consumeChar(':')) {
            return failAt(scan_.peek(), "'Frame Time:' after the frame count");
        }
        const Token timeToken = scan_.next();
        const auto frameTime = parseNumber(timeToken.text);
        if (!frameTime || !(*frameTime > 0)) {
            return failAt(timeToken, "a frame time in seconds (> 0) after 'Frame Time:'");
        }
        clip_.frameCount = static_cast<int>(*frames);
        clip_.frameTimeS = *frameTime;

        // Every value takes at least one character and a separator, so a count the rest of the
        // file cannot hold is refused before anything is allocated for it.
        const long long total = *frames * static_cast<long long>(clip_.channelCount);
        const long long room = static_cast<long long>(scan_.remaining() / 2 + 1);
        if (total > room) {
            return fail(framesToken.line,
                        fmt::format("at most {} frames of {} values (the rest of the file holds "
                                    "no more)",
                                    clip_.channelCount > 0 ? room / clip_.channelCount : room,
                                    clip_.channelCount),
                        fmt::format("'Frames: {}'", *frames));
        }
        clip_.values.reserve(static_cast<std::size_t>(total));
        for (long long i = 0; i < total; ++i) {
            const Token t = scan_.next();
            const auto v = parseNumber(t.text);
            if (!v) {
                return failAt(t, valueDescription(i));
            }
            clip_.values.push_back(*v);
        }
        const Token rest = scan_.next();
        if (!rest.end()) {
            return failAt(rest, fmt::format("the end of the file after {} frames of {} values",
                                            clip_.frameCount, clip_.channelCount));
        }
        return true;
    }

    // "a number for frame 3 of 10, channel Zrotation of joint 'LeftLeg'"
    std::string valueDescription(long long index) const {
        const long long f = index / clip_.channelCount;
        const int c = static_cast<int>(index % clip_.channelCount);
        for (const BvhJoint& j : clip_.joints) {
            const int k = c - j.firstChannel;
            if (k >= 0 && k < static_cast<int>(j.channels.size())) {
                return fmt::format("a number for frame {} of {}, channel {} of joint '{}'", f,
                                   clip_.frameCount,
                                   toString(j.channels[static_cast<std::size_t>(k)]), j.name);
            }
        }
        return fmt::format("a number for frame {} of {}", f, clip_.frameCount);
    }

    Scanner scan_;
    std::string_view source_;
    BvhClip clip_;
    std::vector<bool> sawOffset_;
    std::vector<bool> sawChannels_;
    std::optional<Error> error_;
};

}  // namespace

std::string_view toString(BvhChannel c) {
    switch (c) {
        case BvhChannel::Xposition:
            return "Xposition";
        case BvhChannel::Yposition:
            return "Yposition";
        case BvhChannel::Zposition:
            return "Zposition";
        case BvhChannel::Xrotation:
            return "Xrotation";
        case BvhChannel::Yrotation:
            return "Yrotation";
        case BvhChannel::Zrotation:
            return "Zrotation";
    }
    return "?";
}

std::span<const double> BvhClip::frame(int f) const {
    const auto n = static_cast<std::size_t>(channelCount);
    return std::span<const double>(values).subspan(static_cast<std::size_t>(f) * n, n);
}

int BvhClip::findJoint(std::string_view name) const {
    for (std::size_t i = 0; i < joints.size(); ++i) {
        if (joints[i].name == name) {
            return static_cast<int>(i);
        }
    }
    return -1;
}

std::vector<ImplausibleTurns> implausibleTurns(const BvhClip& clip, double maxRateRadS) {
    std::vector<ImplausibleTurns> out;
    const double maxStepRad = maxRateRadS * clip.frameTimeS;
    Vec3d t;
    Quatd before;
    Quatd after;
    for (int j = 0; j < static_cast<int>(clip.joints.size()); ++j) {
        ImplausibleTurns found{clip.joints[static_cast<std::size_t>(j)].name};
        for (int f = 0; f + 1 < clip.frameCount; ++f) {
            clip.localPose(j, clip.frame(f), t, before);
            clip.localPose(j, clip.frame(f + 1), t, after);
            const double turn = before.angularDistance(after);
            if (turn > maxStepRad) {
                ++found.frames;
                found.maxTurnRad = std::max(found.maxTurnRad, turn);
            }
        }
        if (found.frames > 0) {
            out.push_back(std::move(found));
        }
    }
    return out;
}

void BvhClip::localPose(int joint, std::span<const double> frameValues, Vec3d& translation,
                        Quatd& rotation) const {
    const BvhJoint& j = joints[static_cast<std::size_t>(joint)];
    translation = j.offset;
    rotation = Quatd::Identity();
    constexpr double kRadPerDeg = std::numbers::pi / 180.0;
    for (std::size_t k = 0; k < j.channels.size(); ++k) {
        const double v = frameValues[static_cast<std::size_t>(j.firstChannel) + k];
        switch (j.channels[k]) {
            case BvhChannel::Xposition:
                translation.x() = v;
                break;
            case BvhChannel::Yposition:
                translation.y() = v;
                break;
            case BvhChannel::Zposition:
                translation.z() = v;
                break;
            case BvhChannel::Xrotation:
                rotation = rotation * Quatd(Eigen::AngleAxisd(v * kRadPerDeg, Vec3d::UnitX()));
                break;
            case BvhChannel::Yrotation:
                rotation = rotation * Quatd(Eigen::AngleAxisd(v * kRadPerDeg, Vec3d::UnitY()));
                break;
            case BvhChannel::Zrotation:
                rotation = rotation * Quatd(Eigen::AngleAxisd(v * kRadPerDeg, Vec3d::UnitZ()));
                break;
        }
    }
}

Result<BvhClip> parseBvh(std::string_view text, std::string_view sourceName) {
    constexpr std::string_view kUtf8Bom = "\xEF\xBB\xBF";
    if (text.substr(0, kUtf8Bom.size()) == kUtf8Bom) {
        text.remove_prefix(kUtf8Bom.size());
    }
    return Parser(text, sourceName).run();
}

Result<BvhClip> loadBvh(const std::filesystem::path& path) {
    auto text = readInputFile(path);
    if (!text) {
        return text.error();
    }
    return parseBvh(*text, path.string());
}

}  // namespace caphub::board::sim
