#ifndef FIELDSPACE_FUZZ_TINY_BASES_H_
#define FIELDSPACE_FUZZ_TINY_BASES_H_

// The fixture of the fuzz targets that need a basis: small served bases on a torus built in code
// (core/mesh/shapes.h), one per field kind, built once per process.

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "server/served_basis.h"

namespace fieldspace::fuzz {

// The ids of the files the store fuzzer writes (its seeds are records with these ids).
inline constexpr char kStoreMeshId[] = "m-00000000000000aa";
inline constexpr char kStoreBasisId[] = "b-00000000000000bb";

// 0: vector, 1: 2-field (line field, so that Align has a target), 2: tensor.
inline constexpr int kNumTinyBases = 3;

// Basis `which` (taken modulo kNumTinyBases) on a 192-face torus, d = 20. Aborts the process if
// the fixture cannot be built (a fuzz run without it would test nothing).
const std::shared_ptr<const server::ServedBasis>& TinyBasis(int which);

// The torus as a mesh file of `format` ("obj", "off", "ply"): what LoadMesh's fuzz fixture
// serves and what the seed generator writes.
std::string TinyMeshFile(std::string_view format);

}  // namespace fieldspace::fuzz

#endif  // FIELDSPACE_FUZZ_TINY_BASES_H_
