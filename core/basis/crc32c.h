#ifndef FIELDSPACE_CORE_BASIS_CRC32C_H_
#define FIELDSPACE_CORE_BASIS_CRC32C_H_

#include <cstddef>
#include <cstdint>

namespace fieldspace {

// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), the checksum of iSCSI, ext4 and
// LevelDB: detects every error burst of up to 32 bits, in particular any changed byte.
// Crc32cExtend(Crc32cExtend(0, a), b) == Crc32c of a followed by b. Uses the SSE4.2 instruction
// when the CPU has it (chosen at run time), else a table-driven version; same results either way.
uint32_t Crc32cExtend(uint32_t crc, const void* data, size_t size);
inline uint32_t Crc32c(const void* data, size_t size) { return Crc32cExtend(0, data, size); }

namespace crc32c_internal {
// The table-driven implementation alone (tests compare it with the dispatched one).
uint32_t Crc32cExtendPortable(uint32_t crc, const void* data, size_t size);
}  // namespace crc32c_internal

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_CRC32C_H_
