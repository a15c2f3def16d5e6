#include "ray_tasks.hpp"

namespace tarmac::core::occupancy {

std::uint64_t walk_task(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                        FreeMarks marks, MarkBox& box, int lanes) {
  // The box grows at the end of every ray: it lives on this task's own stack until the task
  // is done. The tasks' boxes share a cache line, and updating them in place while another
  // task did the same cost the walks about a quarter of their time on 2 threads.
  MarkBox local;
  std::uint64_t visits = 0;
  const bool flags = marks.dirty != nullptr;
#if defined(TARMAC_WIDE_WALK)
  if (lanes == 8) {
    visits = walk_rays_lanes8(w, start, rays, marks, local);
  } else if (lanes == 4) {
    visits = walk_rays_lanes4(w, start, rays, marks, local);
  }
#endif
  if (lanes == 1) {
    visits = flags ? walk_rays<true>(w, start, rays, marks, local)
                   : walk_rays<false>(w, start, rays, marks, local);
  }
  box = local;
  return visits;
}

}  // namespace tarmac::core::occupancy
