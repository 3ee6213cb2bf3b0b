// Q-format fixed-point scalars for the orientation filter: Fixed<F> is an int32 with F fraction
// bits, Wide<F> the int64 that a product of two Fixed lands in. The filter code is written once
// over these helpers and over float (docs/fusion.md, "Fixed point").
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace caphub::fusion {

// A value v stored as round(v * 2^F) in an int32: range [-2^(31-F), 2^(31-F)), step 2^-F.
template <int F>
struct Fixed {
    static_assert(F >= 0 && F <= 31, "Fixed<F>: F fraction bits must fit in an int32");
    static constexpr int kFrac = F;
    std::int32_t raw = 0;

    // Saturates outside the range: conversions happen at the filter's edge and in setup, where
    // an out-of-range value must not wrap into a value of the opposite sign. NaN has no side: it
    // becomes the bottom of the range like a value below it, so that the filter's input check
    // (withinLimit) rejects it as it rejects every saturated value: an int32 has no NaN.
    static constexpr Fixed fromDouble(double v) {
        const double scaled = v * static_cast<double>(std::int64_t{1} << F);
        Fixed out;
        if (!(scaled == scaled)) {  // NaN
            out.raw = std::numeric_limits<std::int32_t>::min();
        } else if (scaled >= 2147483647.0) {
            out.raw = std::numeric_limits<std::int32_t>::max();
        } else if (scaled <= -2147483648.0) {
            out.raw = std::numeric_limits<std::int32_t>::min();
        } else {
            out.raw = static_cast<std::int32_t>(scaled < 0 ? scaled - 0.5 : scaled + 0.5);
        }
        return out;
    }
    static constexpr Fixed fromRaw(std::int32_t r) {
        Fixed out;
        out.raw = r;
        return out;
    }
    constexpr double toDouble() const {
        return static_cast<double>(raw) / static_cast<double>(std::int64_t{1} << F);
    }
    // At either end of the range: what fromDouble gives for a value beyond it or for NaN.
    constexpr bool saturated() const {
        return raw == std::numeric_limits<std::int32_t>::max() ||
               raw == std::numeric_limits<std::int32_t>::min();
    }

    constexpr Fixed operator-() const { return fromRaw(-raw); }
    constexpr Fixed& operator+=(Fixed o) {
        raw += o.raw;
        return *this;
    }
    constexpr Fixed& operator-=(Fixed o) {
        raw -= o.raw;
        return *this;
    }
    friend constexpr Fixed operator+(Fixed a, Fixed b) { return fromRaw(a.raw + b.raw); }
    friend constexpr Fixed operator-(Fixed a, Fixed b) { return fromRaw(a.raw - b.raw); }
    friend constexpr bool operator<(Fixed a, Fixed b) { return a.raw < b.raw; }
    friend constexpr bool operator>(Fixed a, Fixed b) { return a.raw > b.raw; }
    friend constexpr bool operator<=(Fixed a, Fixed b) { return a.raw <= b.raw; }
    friend constexpr bool operator>=(Fixed a, Fixed b) { return a.raw >= b.raw; }
    friend constexpr bool operator==(Fixed a, Fixed b) { return a.raw == b.raw; }
};

// A 64-bit intermediate with F fraction bits: products and sums of products. It converts back to
// a Fixed only through scalarCast, which rounds to nearest.
template <int F>
struct Wide {
    static_assert(F >= 0 && F <= 62, "Wide<F>: F fraction bits must fit in an int64");
    static constexpr int kFrac = F;
    std::int64_t raw = 0;

    static constexpr Wide fromRaw(std::int64_t r) {
        Wide out;
        out.raw = r;
        return out;
    }
    constexpr double toDouble() const {
        return static_cast<double>(raw) / static_cast<double>(std::int64_t{1} << F);
    }
    constexpr Wide operator-() const { return fromRaw(-raw); }
    friend constexpr Wide operator+(Wide a, Wide b) { return fromRaw(a.raw + b.raw); }
    friend constexpr Wide operator-(Wide a, Wide b) { return fromRaw(a.raw - b.raw); }
    friend constexpr bool operator<(Wide a, Wide b) { return a.raw < b.raw; }
    friend constexpr bool operator>(Wide a, Wide b) { return a.raw > b.raw; }
};

template <int A, int B>
constexpr Wide<A + B> operator*(Fixed<A> a, Fixed<B> b) {
    return Wide<A + B>::fromRaw(static_cast<std::int64_t>(a.raw) * b.raw);
}

namespace detail {

// x * 2^-shift rounded to nearest (ties away from zero is not needed: ties go up), or x * 2^shift
// for a negative shift.
constexpr std::int64_t roundShift(std::int64_t x, int shift) {
    if (shift <= 0) {
        return x * (std::int64_t{1} << -shift);
    }
    return (x + (std::int64_t{1} << (shift - 1))) >> shift;
}

constexpr std::int32_t saturate32(std::int64_t x) {
    if (x > std::numeric_limits<std::int32_t>::max()) {
        return std::numeric_limits<std::int32_t>::max();
    }
    if (x < std::numeric_limits<std::int32_t>::min()) {
        return std::numeric_limits<std::int32_t>::min();
    }
    return static_cast<std::int32_t>(x);
}

template <typename T>
struct IsFixed : std::false_type {};
template <int F>
struct IsFixed<Fixed<F>> : std::true_type {};

}  // namespace detail

// ---- scalarCast: the one conversion between formats (identity for float). Narrowing to a Fixed
// rounds to nearest and saturates, so an out-of-range intermediate cannot wrap around.
template <typename To, int F>
constexpr To scalarCast(Wide<F> w) {
    if constexpr (detail::IsFixed<To>::value) {
        return To::fromRaw(detail::saturate32(detail::roundShift(w.raw, F - To::kFrac)));
    } else {
        static_assert(sizeof(To) == 0, "scalarCast<Wide>: target must be a Fixed");
    }
}

template <typename To, int F>
constexpr To scalarCast(Fixed<F> x) {
    if constexpr (detail::IsFixed<To>::value) {
        return To::fromRaw(detail::saturate32(
            detail::roundShift(static_cast<std::int64_t>(x.raw), F - To::kFrac)));
    } else {
        static_assert(sizeof(To) == 0, "scalarCast<Fixed>: target must be a Fixed");
    }
}

template <typename To>
constexpr To scalarCast(float x) {
    static_assert(std::is_same_v<To, float>, "a float filter stays in float");
    return x;
}

// ---- Constants and conversions at the edge (setup, inputs, outputs).
template <typename T>
constexpr T fromDouble(double v) {
    if constexpr (detail::IsFixed<T>::value) {
        return T::fromDouble(v);
    } else {
        return static_cast<T>(v);
    }
}

template <typename T>
constexpr double toDouble(T v) {
    if constexpr (std::is_floating_point_v<T>) {
        return static_cast<double>(v);
    } else {
        return v.toDouble();
    }
}

// x / 2, exact for float, rounded for fixed.
template <int F>
constexpr Fixed<F> half(Fixed<F> x) {
    return Fixed<F>::fromRaw(static_cast<std::int32_t>(detail::roundShift(x.raw, 1)));
}
constexpr float half(float x) {
    return 0.5f * x;
}

template <int F>
constexpr Fixed<F> twice(Fixed<F> x) {
    return Fixed<F>::fromRaw(detail::saturate32(static_cast<std::int64_t>(x.raw) * 2));
}
constexpr float twice(float x) {
    return 2.0f * x;
}

template <int F>
constexpr Fixed<F> absOf(Fixed<F> x) {
    return x.raw < 0 ? -x : x;
}
inline float absOf(float x) {
    return std::fabs(x);
}

template <typename T>
constexpr T zeroOf() {
    return fromDouble<T>(0.0);
}

// ---- Inverse square root. For fixed point: Newton iterations y <- y (3 - x y^2) / 2 seeded from a
// table, all in integers, no division. Input Wide<F> (a sum of squares), output Q30 (the caller
// scales a vector of magnitude ~1 with it).

namespace detail {

inline int leadingBit(std::uint64_t x) {
    return 63 - __builtin_clzll(x);
}

// One Newton step of 1/sqrt(v) for v and y in Q30: (3 - v y^2) / 2 times y.
constexpr std::int64_t rsqrtStepQ30(std::int64_t y, std::int64_t vQ30) {
    const std::int64_t y2 = (y * y) >> 30;       // Q30
    const std::int64_t vy2 = (vQ30 * y2) >> 30;  // Q30
    return (y * ((std::int64_t{3} << 30) - vy2)) >> 31;
}

// The seeds: 1/sqrt(v) in Q30 at the middle of each of the 385 intervals of 2^-9 that cover v in
// [0.25, 1] (entry i: vQ30 in [(i + 128) 2^21, (i + 129) 2^21)), each from the linear fit
// 1/sqrt(v) ~ 2.2 - 1.2 v (within 4 %) and four Newton steps. Built when compiling.
inline constexpr int kRsqrtSeedShift = 21;
inline constexpr int kRsqrtSeedFirst = 128;  // 2^28 >> 21: v = 0.25
inline constexpr auto kRsqrtSeedsQ30 = [] {
    std::array<std::int32_t, 385> seeds{};
    for (std::size_t i = 0; i < seeds.size(); ++i) {
        const std::int64_t vQ30 =
            (static_cast<std::int64_t>(i + kRsqrtSeedFirst) << kRsqrtSeedShift) +
            (std::int64_t{1} << (kRsqrtSeedShift - 1));
        std::int64_t y = std::int64_t{2362232013} - ((std::int64_t{1288490189} * vQ30) >> 30);
        for (int k = 0; k < 4; ++k) {
            y = rsqrtStepQ30(y, vQ30);
        }
        seeds[i] = static_cast<std::int32_t>(y);
    }
    return seeds;
}();
static_assert(kRsqrtSeedsQ30.front() > (std::int32_t{1} << 30) + (std::int32_t{1} << 29) &&
                  kRsqrtSeedsQ30.back() > (std::int32_t{1} << 29),
              "the seeds lie in (1.5, 2) at v = 0.25 and near 1 at v = 1: an int32 holds them");

// 1/sqrt(m * 2^-60) for m in [2^58, 2^60] (value in [0.25, 1]): result in Q30, in [1, 2]. The seed
// is within 0.2 % of the truth (half an interval's width); two Newton steps (the relative error
// goes to 1.5 e^2 each time) leave 5e-11, below the truncations of the steps themselves: every
// input's result is within 1.24 steps of Q30 of the exact value (checked on all 2^30 - 2^28
// inputs; the four steps from the linear fit that this replaced were within 1.21, at twice the
// cost on the per-sample path).
inline std::int64_t rsqrtNormalizedQ30(std::int64_t mQ60) {
    const std::int64_t vQ30 = mQ60 >> 30;
    std::int64_t y =
        kRsqrtSeedsQ30[static_cast<std::size_t>((vQ30 >> kRsqrtSeedShift) - kRsqrtSeedFirst)];
    y = rsqrtStepQ30(y, vQ30);
    return rsqrtStepQ30(y, vQ30);
}

}  // namespace detail

// Normalises a vector of any Fixed format in place into Q30 unit components. Returns false (and
// leaves the output unchanged) for a zero vector. The input is first shifted so that its largest
// component lies in [2^29, 2^30): the sum of squares then fits an int64 whatever the format.
template <int F, int N>
bool normalizeToQ30(const Fixed<F> (&in)[N], Fixed<30> (&out)[N]) {
    std::uint32_t maxAbs = 0;
    for (int i = 0; i < N; ++i) {
        const std::int64_t v = in[i].raw;
        const std::uint32_t a = static_cast<std::uint32_t>(v < 0 ? -v : v);
        maxAbs = a > maxAbs ? a : maxAbs;
    }
    if (maxAbs == 0) {
        return false;
    }
    const int shift = 29 - detail::leadingBit(maxAbs);  // left shift to put the top bit at 29
    std::int64_t s[N];
    std::int64_t sumSq = 0;
    for (int i = 0; i < N; ++i) {
        s[i] = shift >= 0 ? static_cast<std::int64_t>(in[i].raw) << shift
                          : static_cast<std::int64_t>(in[i].raw) >> -shift;
        sumSq += s[i] * s[i];  // < N * 2^60
    }
    // sumSq is in [2^58, N 2^60]; bring it to [2^58, 2^60] by an even shift (a factor 4^k),
    // which scales the inverse square root by 2^k.
    int k = 0;
    while (sumSq > (std::int64_t{1} << 60)) {
        sumSq >>= 2;
        ++k;
    }
    const std::int64_t r = detail::rsqrtNormalizedQ30(sumSq);  // Q30, in [1, 2]
    for (int i = 0; i < N; ++i) {
        // s[i] (Q30-scaled) * r (Q30) / 2^k -> Q30
        const std::int64_t p = s[i] * r;  // < 2^30 * 2^31
        out[i] = Fixed<30>::fromRaw(detail::saturate32(detail::roundShift(p, 30 + k)));
    }
    return true;
}

}  // namespace caphub::fusion
