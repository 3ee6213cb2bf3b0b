// CRC-32C (Castagnoli; reflected polynomial 0x82F63B78), the checksum of every .cap record.
// Debian 12 ships no C/C++ CRC-32C library, so it is computed here: slicing-by-8 tables.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace caphub::firmware {

// Continues a CRC: pass the previous result to extend it (start with 0).
std::uint32_t crc32c(std::span<const std::uint8_t> data, std::uint32_t crc = 0);

}  // namespace caphub::firmware
