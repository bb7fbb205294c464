// Renderer: placeholder until implemented.
#include "slimrt/render.h"

namespace slim {
Camera frame_box(const Box3f&, int, int) { throw Error("frame_box: not implemented yet"); }
Image render(const Scene&, const Camera&, const RenderOptions&) { throw Error("render: not implemented yet"); }
void write_image(const Image&, const std::string& path) { throw Error(path + ": not implemented yet"); }
double psnr(const Image&, const Image&) { return 0; }
}  // namespace slim
