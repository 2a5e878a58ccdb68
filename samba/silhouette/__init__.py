"""Single-camera markerless capture (Okada, Stenger, Kondoh): silhouettes extracted from
video (background subtraction, or a learnt person segmenter without an empty stage),
silhouettes of the body model rendered for database poses, the shape tree built
from them, and the tree-based Bayesian tracker.
"""

from samba.silhouette.distance import downsampled
from samba.silhouette.evaluation import staged
from samba.silhouette.extraction import BACKGROUND_METHODS, SilhouetteExtractor
from samba.silhouette.person_render import empty_stage_frames, person_frames, stage_background
from samba.silhouette.person_segmentation import PersonSegmenter, SegmenterError
from samba.silhouette.render import noisy_silhouettes, render_silhouettes
from samba.silhouette.runs import SilhouetteRuns
from samba.silhouette.shape_tree import ShapeTree, TreeLevel
from samba.silhouette.tracker import SilhouetteTracker
from samba.silhouette.view import SilhouetteView

__all__ = [
    "BACKGROUND_METHODS",
    "PersonSegmenter",
    "SegmenterError",
    "ShapeTree",
    "SilhouetteExtractor",
    "SilhouetteRuns",
    "SilhouetteTracker",
    "SilhouetteView",
    "TreeLevel",
    "downsampled",
    "empty_stage_frames",
    "noisy_silhouettes",
    "person_frames",
    "render_silhouettes",
    "stage_background",
    "staged",
]
