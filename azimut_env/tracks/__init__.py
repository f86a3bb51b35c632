"""Reference tracks for an omnidirectional robot: a path, a heading profile independent of the path
direction, and a speed profile.

- :mod:`.track`: :class:`Track` (progress s with ``ds = sqrt(dℓ² + (ρ dθ)²)``, so that a rotation in
  place has progress; sampling, projection, errors, look-ahead, :meth:`Track.from_waypoints`).
- :mod:`.library`: the built-in tracks, :func:`make_track` and :data:`TRACK_NAMES`.
- :mod:`.scenarios`: the scenario tracks, scaled to a robot (:func:`scenario_track`,
  :data:`SCENARIO_NAMES`), and :func:`named_track` for any name of :data:`ALL_TRACK_NAMES`.
- :mod:`.query`: the compiled queries (one kernel for one robot, N robots on one track and N
  robots on N tracks) and the scalar helpers other compiled code shares.
"""

from azimut_env.tracks.library import (
                      TRACK_NAMES,
                      circle_track,
                      crab_track,
                      figure8_track,
                      make_track,
                      paper_track,
                      random_track,
                      square_track,
)
from azimut_env.tracks.query import (
                      TQ,
                      interp1,
                      np_interp1,
                      project_window_kernel,
                      query_batch_kernel,
                      query_one_kernel,
                      query_tracks,
                      wrap_angle,
                      wrap_pi,
                      wrap_progress,
)
from azimut_env.tracks.scenarios import ALL_TRACK_NAMES, SCENARIO_NAMES, named_track, scenario_track
from azimut_env.tracks.track import Track

__all__ = ["Track", "TQ", "make_track", "query_tracks", "TRACK_NAMES", "SCENARIO_NAMES", "ALL_TRACK_NAMES",
           "scenario_track", "named_track", "wrap_angle", "wrap_pi", "interp1", "np_interp1",
           "wrap_progress", "project_window_kernel", "query_one_kernel", "query_batch_kernel", "paper_track",
           "circle_track", "figure8_track", "square_track", "crab_track", "random_track"]
