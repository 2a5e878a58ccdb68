"""The marker chain, from camera images to labelled 3D markers: blob detection, per-camera
tracking, cross-view and leg labelling, stage tracking and the search for the standard
pose, gap filling of 3D marker trajectories, plus the synthetic marker cameras (rendering,
the observation model, lead-in).
"""

from samba.markers.camera_chain import EMPTY_STAGE_FRAMES, run_chain
from samba.markers.cross_view_labels import CrossViewSettings
from samba.markers.detection import detect_markers, static_mask
from samba.markers.gap_filling import fill_gaps
from samba.markers.lead_in import LeadIn, standing_lead_in
from samba.markers.observation import (
    evaluation_cameras,
    new_user_factors,
    observe_markers,
    scale_limbs,
    spread_cameras,
)
from samba.markers.render import RenderOptions, film_empty_stage, render_camera
from samba.markers.stage_tracking import StageTracker
from samba.markers.tracking import MarkerTracker

__all__ = [
    "EMPTY_STAGE_FRAMES",
    "CrossViewSettings",
    "LeadIn",
    "MarkerTracker",
    "RenderOptions",
    "StageTracker",
    "detect_markers",
    "evaluation_cameras",
    "fill_gaps",
    "film_empty_stage",
    "new_user_factors",
    "observe_markers",
    "render_camera",
    "run_chain",
    "scale_limbs",
    "spread_cameras",
    "standing_lead_in",
    "static_mask",
]
