"""The track stage of the pipeline: each robot's true track state and look-ahead.

:func:`track` projects the true chassis pose of each robot of ``rows`` on its own track
(``ta.packs[i]``, one compiled query, :func:`azimut_env.tracks.query_one_kernel`), starting from
its progress before the step (``ta.s``, kept in ``ta.s_prev``; at a reset, the start progress the
reset put there): the track state ``ta.track_out`` (columns :class:`~azimut_env.tracks.TQ`), its
columns ``ta.s``, ``ta.lat``, ``ta.head``, ``ta.v_ref``, the look-ahead ``ta.look`` (K, 3) and the
chassis speed along the path ``ta.v_along``. The reward and the termination read these (the
ground truth, whatever the observation's pose source).
"""

from __future__ import annotations

from numba import njit

from azimut_env.physics.layout import RS
from azimut_env.task.observation import speed_along_xy
from azimut_env.tracks import TQ, query_one_kernel

__all__ = ["track", "BACK", "AHEAD"]

#: the projection's window around the progress before the step [m]
BACK, AHEAD = 0.5, 1.0

# plain-int columns (numba folds them; the IntEnums stay the names)
_RS_X, _RS_Y, _RS_TH, _RS_VX, _RS_VY = int(RS.X), int(RS.Y), int(RS.TH), int(RS.VX), int(RS.VY)
_TQ_S, _TQ_LATERAL, _TQ_HEADING, _TQ_V_REF, _TQ_PSI = (int(TQ.S), int(TQ.LATERAL), int(TQ.HEADING), int(TQ.V_REF),
                                                      int(TQ.PSI))


@njit(cache=True)
def track(ta, rows, action):
    """The true track state of the robots of ``rows`` (see the module docstring)."""
    summary, out = ta.summary, ta.track_out
    for i in range(rows.shape[0]):
        if rows[i]:
            ta.s_prev[i] = ta.s[i]
            query_one_kernel(ta.packs[i], ta.track_closed[i], ta.track_length[i], ta.track_rho[i], summary[i, _RS_X],
                             summary[i, _RS_Y], summary[i, _RS_TH], ta.s_prev[i], BACK, AHEAD, ta.lookahead_spacing,
                             out[i], ta.look[i])
            ta.s[i] = out[i, _TQ_S]
            ta.lat[i] = out[i, _TQ_LATERAL]
            ta.head[i] = out[i, _TQ_HEADING]
            ta.v_ref[i] = out[i, _TQ_V_REF]
            ta.v_along[i] = speed_along_xy(summary[i, _RS_VX], summary[i, _RS_VY], out[i, _TQ_PSI])
