// placeholder
#include "slimrt/scene.h"
