/// The memory layout of fixed-size Eigen members as compiled into this library.
///
/// Eigen aligns a fixed-size vectorizable object (Vec4, Mat4, Mat34, ...) to EIGEN_MAX_STATIC_ALIGN_BYTES,
/// whose default follows the compiler flags: 16 bytes for a default x86-64 build, 32 with AVX, 64 with
/// AVX-512. The structs in these headers would then have one layout in the library and another in a
/// package built with other flags. The library is built with EIGEN_MAX_STATIC_ALIGN_BYTES=16 and exports
/// that definition to the packages that find it (CMakeLists.txt, cmake/active_tensegrity-extras.cmake.in),
/// so they see its layout whatever their flags; test/downstream compares its own numbers with these.
#pragma once

#include <cstddef>

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
/// A struct whose member offset moves with the alignment of fixed-size Eigen vectors: 16 with the
/// exported definition, 32 when compiled with AVX without it.
struct EigenLayoutProbe
{
  double scalar = 0.0;
  Vec4 vector = Vec4::Zero();
};

/// sizeof, alignof and the offset of one named member of a type.
struct TypeLayout
{
  std::size_t size = 0;
  std::size_t align = 0;
  std::size_t member_offset = 0;
};

struct EigenLayout
{
  int max_static_align_bytes = 0;  // EIGEN_MAX_STATIC_ALIGN_BYTES
  TypeLayout probe;                // EigenLayoutProbe, member `vector`
  TypeLayout constraint;           // Constraint (model.h), member `coefficients`
  TypeLayout model;                // Model (model.h), member `gravity`
  TypeLayout state;                // State (state.h), member `natural`
};

/// The layout as the library was compiled (src/core/outputs/eigen_layout.cpp).
EigenLayout libraryEigenLayout();

}  // namespace active_tensegrity::core
