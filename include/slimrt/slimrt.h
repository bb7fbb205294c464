// slimrt: compact CPU ray tracing of huge triangle and quad meshes. Umbrella header.
#pragma once

#include "slimrt/costa.h"
#include "slimrt/error.h"
#include "slimrt/grids.h"
#include "slimrt/math.h"
#include "slimrt/mesh.h"
#include "slimrt/pairing.h"
#include "slimrt/render.h"
#include "slimrt/scene.h"
