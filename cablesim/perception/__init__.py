"""Perception of the grasped hose from a frame stream (SPEC sections 2, 4, 5, 7, 8).

Plain NumPy/OpenCV; torch is imported lazily by the RAFT back end only; MuJoCo never.

Typical use::

    from cablesim.perception import segment_stream, DISFlow, GraspSampler
    seg = segment_stream(stream, method="correlation", flow=DISFlow())   # or "published", ...
    votes = seg.votes                       # actions supporting each target pixel
    res = GraspSampler(reachability=robot_check).propose(votes, target.depth, target.intrinsics)

Flow back ends (:class:`FlowEstimator`) and segmentation methods (:class:`SegmentationMethod`)
are plug-ins: the built-ins are registered in :data:`FLOW_BACKENDS` and
:data:`SEGMENTATION_METHODS`; a user's own is reached by an installed package's entry point
(groups ``cablesim.flows``, ``cablesim.methods``) or as ``MODULE:CLASS`` wherever a name is
asked for (``docs/plugins.md``).
"""

from cablesim.frames import (
    LABEL_BACKGROUND,
    LABEL_ROBOT,
    TARGET_ACTION,
    Frame,
    FrameTruth,
    Intrinsics,
    Stream,
)
from cablesim.perception.actions import (
    action_direction,
    gripper_displacements,
    subsample_by_gripper,
)
from cablesim.perception.correlation import (
    AblationParams,
    CorrelationAccumulator,
    CorrelationParams,
    CorrelationResult,
    moments_to_result,
)
from cablesim.perception.flow import (
    FLOW_BACKENDS,
    DISFlow,
    FarnebackFlow,
    FlowEstimator,
    GateParams,
    OracleFlow,
    check_flow,
    flow_names,
    make_flow,
    texture_mask,
)
from cablesim.perception.flow_region import FlowRegion, RegionFlow
from cablesim.perception.geometry import (
    SegmentPose,
    eccentricity,
    geometric_median,
    segment_pose,
)
from cablesim.perception.grasp_sampler import (
    Candidate,
    GraspProposal,
    GraspSampler,
    GraspSamplerParams,
    SamplingResult,
)
from cablesim.perception.methods import (
    SEGMENTATION_METHODS,
    PerActionAccumulator,
    SegmentationMethod,
    StreamContext,
    check_method,
    make_method,
    method_names,
)
from cablesim.perception.metrics import (
    BETAS,
    GRADES,
    MaskScores,
    confusion,
    f_beta,
    f_beta_counts,
    flow_epe,
    grade_proposal,
    mean_scores,
    movingcables_frame,
    movingcables_summary,
    nanmean,
    score_mask,
)
from cablesim.perception.pipeline import (
    CURRENT_METHODS,
    METHODS,
    StreamSegmentation,
    StreamStatistics,
    compute_statistics,
    iter_flows,
    masks_from_statistics,
    segment_from_statistics,
    segment_stream,
)
from cablesim.perception.published import (
    PUBLISHED_METHODS,
    PUBLISHED_THRESHOLDS,
    PublishedParams,
    PublishedResult,
    PublishedSegmentationResult,
)
from cablesim.perception.segmentation import (
    SegmentationAccumulator,
    SegmentationParams,
    SegmentationResult,
)
from cablesim.perception.tuning import TuningResult, tune_thresholds, tuning_table
from cablesim.perception.votes import (
    VoteAccumulator,
    intersection,
    merge_votes,
    union,
    vote_image,
)

__all__ = [
    "BETAS",
    "CURRENT_METHODS",
    "FLOW_BACKENDS",
    "GRADES",
    "LABEL_BACKGROUND",
    "LABEL_ROBOT",
    "METHODS",
    "PUBLISHED_METHODS",
    "PUBLISHED_THRESHOLDS",
    "SEGMENTATION_METHODS",
    "TARGET_ACTION",
    "AblationParams",
    "Candidate",
    "CorrelationAccumulator",
    "CorrelationParams",
    "CorrelationResult",
    "DISFlow",
    "FarnebackFlow",
    "FlowEstimator",
    "FlowRegion",
    "Frame",
    "FrameTruth",
    "GateParams",
    "GraspProposal",
    "GraspSampler",
    "GraspSamplerParams",
    "Intrinsics",
    "MaskScores",
    "OracleFlow",
    "PerActionAccumulator",
    "PublishedParams",
    "PublishedResult",
    "PublishedSegmentationResult",
    "RegionFlow",
    "SamplingResult",
    "SegmentPose",
    "SegmentationMethod",
    "SegmentationAccumulator",
    "SegmentationParams",
    "SegmentationResult",
    "Stream",
    "StreamSegmentation",
    "StreamContext",
    "StreamStatistics",
    "TuningResult",
    "VoteAccumulator",
    "action_direction",
    "check_flow",
    "check_method",
    "compute_statistics",
    "confusion",
    "eccentricity",
    "f_beta",
    "f_beta_counts",
    "flow_names",
    "flow_epe",
    "geometric_median",
    "grade_proposal",
    "gripper_displacements",
    "intersection",
    "iter_flows",
    "make_flow",
    "make_method",
    "masks_from_statistics",
    "mean_scores",
    "movingcables_frame",
    "movingcables_summary",
    "nanmean",
    "merge_votes",
    "method_names",
    "moments_to_result",
    "score_mask",
    "segment_from_statistics",
    "segment_pose",
    "segment_stream",
    "subsample_by_gripper",
    "texture_mask",
    "tune_thresholds",
    "tuning_table",
    "union",
    "vote_image",
]
