#include "firmware/export/pose_track.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "board/loader.h"

namespace caphub::firmware::exporter {

namespace {

// A pose record as stored: single precision, like the file.
struct RawPose {
    std::int64_t tNs = 0;
    Eigen::Vector3f rootM;
    std::array<Eigen::Quaternionf, body::kSegmentCount> q;
    std::uint32_t notMeasured = 0;
};

bool finite(const Eigen::Vector3f& v) {
    return v.allFinite();
}

// Highest export rate accepted: far above any IMU pose rate, low enough to keep a typo such as
// --rate 1e9 from filling the disk.
constexpr double kMaxRateHz = 10000;
// The most frames one track holds (each about 360 bytes: a 20-minute take at 1000 Hz is 1.2
// million). A rate or a span beyond it (a pose record dated days after the others) is refused,
// not allocated until memory runs out.
constexpr double kMaxFrames = 4e6;

}  // namespace

namespace {

// The board file a recording's metadata carries, loaded; or why there is none.
std::optional<board::Board> boardFromMetadata(const std::string& metadataToml, std::string& why) {
    std::string boardText;
    try {
        const toml::table meta =
            toml::parse(std::string_view(metadataToml), std::string_view("recording metadata"));
        if (const auto text = meta["board"]["text"].value<std::string>()) {
            boardText = *text;
        }
    } catch (const toml::parse_error& e) {
        why = fmt::format("the recording's metadata is not TOML ({})", e.description());
        return std::nullopt;
    }
    if (boardText.empty()) {
        why = "the recording carries no board file";
        return std::nullopt;
    }
    board::LoadResult loaded = board::loadBoardText(boardText, "recording's board file");
    if (!loaded.ok()) {
        why = fmt::format("the recording's board file does not load ({})",
                          loaded.errors.empty() ? "?" : loaded.errors.front().str());
        return std::nullopt;
    }
    return std::move(loaded.board);
}

// A [body_calibration] metadata record's calibration, if it is one.
std::optional<body::BodyCalibration> bodyCalibrationOf(const RecordView& v) {
    const std::string_view text(reinterpret_cast<const char*>(v.payload.data()), v.payload.size());
    if (text.find("[body_calibration]") == std::string_view::npos) {
        return std::nullopt;
    }
    try {
        const toml::table meta = toml::parse(text, std::string_view("metadata record"));
        const auto cal = meta["body_calibration"]["text"].value<std::string>();
        if (!cal) {
            return std::nullopt;
        }
        auto parsed = body::parseBodyCalibration(*cal, "body calibration record");
        if (!parsed) {
            return std::nullopt;
        }
        return *parsed;
    } catch (const toml::parse_error&) {
        return std::nullopt;
    }
}

}  // namespace

Quatd mountingAt(const PoseTrack& track, board::Segment segment, double tS) {
    const int s = static_cast<int>(segment);
    const MountingChange* chosen = nullptr;
    for (const auto& c : track.calibrations) {
        if (!body::has(c.mask, s)) {
            continue;
        }
        if (chosen == nullptr || c.tS <= tS) {
            chosen = &c;
        }
        if (c.tS > tS) {
            break;
        }
    }
    return chosen != nullptr ? chosen->mounting[static_cast<std::size_t>(s)]
                             : track.nominalMounting[static_cast<std::size_t>(s)];
}

body::Dimensions dimensionsFromMetadata(const std::string& metadataToml, std::string& source,
                                        board::SubjectConfig& subject) {
    subject = board::SubjectConfig{};
    body::Dimensions fallback = *body::dimensionsFromSubject(board::SubjectConfig{});
    std::string boardText;
    try {
        const toml::table meta =
            toml::parse(std::string_view(metadataToml), std::string_view("recording metadata"));
        if (const auto text = meta["board"]["text"].value<std::string>()) {
            boardText = *text;
        }
    } catch (const toml::parse_error& e) {
        source = fmt::format("default subject (1.75 m): the recording's metadata is not TOML ({})",
                             e.description());
        return fallback;
    }
    if (boardText.empty()) {
        source = "default subject (1.75 m): the recording carries no board file";
        return fallback;
    }
    const board::LoadResult loaded = board::loadBoardText(boardText, "recording's board file");
    if (!loaded.ok()) {
        source =
            fmt::format("default subject (1.75 m): the recording's board file does not load ({})",
                        loaded.errors.empty() ? "?" : loaded.errors.front().str());
        return fallback;
    }
    auto dims = body::dimensionsFromSubject(loaded.board->subject);
    if (!dims) {
        source = fmt::format("default subject (1.75 m): {}", dims.error().message);
        return fallback;
    }
    source = fmt::format("subject of board '{}' ({} m)", loaded.board->name,
                         loaded.board->subject.heightM);
    subject = loaded.board->subject;
    return *dims;
}

PoseFrame interpolate(const PoseFrame& a, const PoseFrame& b, double alpha) {
    PoseFrame out;
    out.tS = a.tS + alpha * (b.tS - a.tS);
    out.rootM = a.rootM + alpha * (b.rootM - a.rootM);
    for (std::size_t j = 0; j < out.qLocal.size(); ++j) {
        out.qLocal[j] = a.qLocal[j].slerp(alpha, b.qLocal[j]).normalized();  // shorter arc
    }
    out.notMeasured = a.notMeasured | b.notMeasured;
    return out;
}

std::vector<NotMeasuredSpan> notMeasuredSpans(const PoseTrack& track) {
    std::vector<NotMeasuredSpan> spans;
    for (int s = 0; s < body::kSegmentCount; ++s) {
        const std::uint32_t bit = 1u << s;
        std::optional<NotMeasuredSpan> open;
        for (const PoseFrame& f : track.frames) {
            if ((f.notMeasured & bit) != 0) {
                if (!open) {
                    open = NotMeasuredSpan{static_cast<board::Segment>(s), f.tS, f.tS};
                }
                open->toS = f.tS;
            } else if (open) {
                spans.push_back(*open);
                open.reset();
            }
        }
        if (open) {
            spans.push_back(*open);
        }
    }
    return spans;
}

namespace {

PoseFrame toFrame(const RawPose& p, std::int64_t t0Ns) {
    PoseFrame f;
    f.tS = static_cast<double>(p.tNs - t0Ns) * 1e-9;
    f.rootM = p.rootM.cast<double>();
    f.notMeasured = p.notMeasured;
    for (std::size_t j = 0; j < p.q.size(); ++j) {
        f.qLocal[j] = normalizedOrIdentity(p.q[j].cast<double>());
    }
    return f;
}

}  // namespace

Result<PoseTrack> readPoseTrack(RecordingReader& reader, const TrackOptions& options,
                                std::uint64_t fileBytes, const ProgressFn& progress) {
    if (options.rateHz && !(*options.rateHz > 0 && *options.rateHz <= kMaxRateHz)) {
        return Error{EINVAL, fmt::format("--rate {}: expected a rate above 0 and at most {} Hz",
                                         *options.rateHz, kMaxRateHz)};
    }
    if (options.fromS && !(*options.fromS >= 0 && std::isfinite(*options.fromS))) {
        return Error{EINVAL, fmt::format("--from {}: expected seconds >= 0", *options.fromS)};
    }
    if (options.toS &&
        !(std::isfinite(*options.toS) && *options.toS >= options.fromS.value_or(0))) {
        return Error{EINVAL, fmt::format("--to {}: expected seconds >= --from ({})", *options.toS,
                                         options.fromS.value_or(0))};
    }

    PoseTrack track;
    track.dimensions =
        dimensionsFromMetadata(reader.metadata(), track.subjectSource, track.subject);
    track.nominalMounting.fill(Quatd::Identity());
    std::string noBoard;
    if (const auto b = boardFromMetadata(reader.metadata(), noBoard)) {
        for (const auto& s : b->sensors) {
            track.sensors.push_back({s.name, s.segment});
            track.nominalMounting[static_cast<std::size_t>(s.segment)] = s.mounting;
        }
    }
    std::vector<std::pair<std::int64_t, body::BodyCalibration>> calibrations;

    std::vector<RawPose> raw;
    RecordView v;
    Eigen::Vector3f rootM;
    std::vector<Eigen::Quaternionf> joints;
    std::uint32_t notMeasured = 0;
    int rc = 0;
    std::uint64_t sinceProgress = 0;
    while ((rc = reader.next(v)) == 1) {
        if (progress && fileBytes > 0 && ++sinceProgress == 4096) {
            sinceProgress = 0;
            progress(std::min(1.0, static_cast<double>(v.offset) / static_cast<double>(fileBytes)));
        }
        if (v.type == cap::RecordType::Metadata) {
            if (auto cal = bodyCalibrationOf(v)) {
                calibrations.emplace_back(toNs(v.t), *cal);
            }
            continue;
        }
        if (v.type != cap::RecordType::Pose) {
            continue;
        }
        if (!decodePose(v, rootM, joints, &notMeasured) || joints.size() != body::kSegmentCount ||
            !finite(rootM) ||
            !std::all_of(joints.begin(), joints.end(), [](const Eigen::Quaternionf& q) {
                // A rotation: a zero quaternion (a crafted or damaged record whose
                // checksum holds) was exported as the identity.
                return q.coeffs().allFinite() && std::abs(q.norm() - 1.0f) < 0.1f;
            })) {
            ++track.malformedPoses;
            continue;
        }
        const std::int64_t tNs = toNs(v.t);
        if (!raw.empty() && tNs <= raw.back().tNs) {
            ++track.outOfOrderPoses;
            continue;
        }
        RawPose& p = raw.emplace_back();
        p.tNs = tNs;
        p.rootM = rootM;
        std::copy(joints.begin(), joints.end(), p.q.begin());
        p.notMeasured = notMeasured & ((1u << body::kSegmentCount) - 1);
    }
    if (rc < 0) {
        return errnoError(rc, "reading the recording");
    }
    for (const auto& d : reader.damage()) {
        track.damagedBytes += d.bytes;
        ++track.damageRanges;
    }
    track.tornTailBytes = reader.tornTailBytes();
    track.poseRecords = raw.size();
    if (raw.empty()) {
        return Error{ENODATA,
                     track.malformedPoses > 0
                         ? fmt::format("no usable pose records ({} malformed: not {} joints, "
                                       "not finite or not rotations)",
                                       track.malformedPoses, body::kSegmentCount)
                         : std::string("no pose records: was the body stage on?")};
    }

    const std::int64_t t0 = raw.front().tNs;
    // In double: a damaged record's time may be anywhere in the 64-bit range.
    track.recordingDurationS =
        (static_cast<double>(raw.back().tNs) - static_cast<double>(t0)) * 1e-9;
    std::stable_sort(calibrations.begin(), calibrations.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [tNs, cal] : calibrations) {
        track.calibrations.push_back(
            {static_cast<double>(tNs - t0) * 1e-9, cal.mask, cal.mounting});
    }
    if (raw.size() >= 2) {
        // The median interval: robust to the gaps that dropped or damaged records leave.
        std::vector<std::int64_t> dt(raw.size() - 1);
        for (std::size_t i = 1; i < raw.size(); ++i) {
            dt[i - 1] = raw[i].tNs - raw[i - 1].tNs;
        }
        std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2),
                         dt.end());
        track.recordedRateHz = 1e9 / static_cast<double>(dt[dt.size() / 2]);
    }
    // One pose has no rate of its own: it becomes one frame at 100 Hz unless told otherwise.
    track.rateHz = options.rateHz.value_or(track.recordedRateHz > 0 ? track.recordedRateHz : 100);

    const double fromS = options.fromS.value_or(0);
    const double toS =
        std::min(options.toS.value_or(track.recordingDurationS), track.recordingDurationS);
    if (fromS > track.recordingDurationS) {
        return Error{EINVAL, fmt::format("--from {} s: the poses end at {:.3f} s", fromS,
                                         track.recordingDurationS)};
    }
    // Frames at fromS + k / rate up to toS: how many, checked before any is made.
    const double frames = std::floor((toS - fromS) * track.rateHz + 1e-6) + 1;
    if (!(frames <= kMaxFrames)) {
        return Error{EFBIG, fmt::format("{:.0f} frames ({:.3f} s at {:g} Hz): more than the {:.0f} "
                                        "one export holds; export a part (--from, --to) or at a "
                                        "lower --rate",
                                        frames, toS - fromS, track.rateHz, kMaxFrames)};
    }
    const auto frameCount = static_cast<std::int64_t>(frames);
    const std::int64_t startNs = t0 + std::llround(fromS * 1e9);
    const double periodNs = 1e9 / track.rateHz;
    track.frames.reserve(static_cast<std::size_t>(frameCount));
    std::size_t i = 0;  // raw[i].tNs <= t < raw[i + 1].tNs
    for (std::int64_t k = 0; k < frameCount; ++k) {
        const std::int64_t t = startNs + std::llround(static_cast<double>(k) * periodNs);
        while (i + 1 < raw.size() && raw[i + 1].tNs <= t) {
            ++i;
        }
        if (raw[i].tNs == t || i + 1 == raw.size()) {
            track.frames.push_back(toFrame(raw[i], t0));
        } else {
            const double alpha = static_cast<double>(t - raw[i].tNs) /
                                 static_cast<double>(raw[i + 1].tNs - raw[i].tNs);
            track.frames.push_back(
                interpolate(toFrame(raw[i], t0), toFrame(raw[i + 1], t0), alpha));
        }
        track.frames.back().tS = static_cast<double>(t - t0) * 1e-9;
    }
    if (progress) {
        progress(1.0);
    }
    return track;
}

}  // namespace caphub::firmware::exporter
