"""Correlation filter tracking with trajectory-guided peak selection (paper: "Tracking with trajectory estimates").

Features, the DCF tracker and its score maps, the choice of a peak near a predicted location,
the colour-model refinement of the output box, and the guided tracker that runs them per frame.
"""

from trade.tracking.colour_box import BoxRefinement, ColourBoxConfig, ColourBoxRefiner
from trade.tracking.dcf import DcfConfig, DcfTracker
from trade.tracking.features import FeatureConfig, extract_features
from trade.tracking.guided import GuidedTracker, TrackedFrame
from trade.tracking.guided_config import GuidedTrackerConfig
from trade.tracking.peaks import PeakChoice, PeakConfig, ResponseMap, highest_peak, select_peak
from trade.tracking.scale import ScaleConfig
from trade.tracking.window import sample_windows

__all__ = [
    "BoxRefinement",
    "ColourBoxConfig",
    "ColourBoxRefiner",
    "DcfConfig",
    "DcfTracker",
    "FeatureConfig",
    "GuidedTracker",
    "GuidedTrackerConfig",
    "PeakChoice",
    "PeakConfig",
    "ResponseMap",
    "ScaleConfig",
    "TrackedFrame",
    "extract_features",
    "highest_peak",
    "sample_windows",
    "select_peak",
]
