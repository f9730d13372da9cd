// The headers nearly every test file includes, compiled once for all the gtest executables
// (CMakeLists.txt: target_precompile_headers with REUSE_FROM) instead of once per test file: gtest, Eigen
// and the core's scene, observables and run headers (which bring the model, the state, the solvers and Eigen's
// sparse LU). The compiler includes it before a test file's first line; each test file still includes what
// it uses, so it also compiles without it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"
