"""Recorded sequences (docs/sequence_format.md): the format, its writer and reader, the recording wrapper and
the open-loop replay of the stack (`trade-replay`).
"""

from trade_gym.quiet_import import import_pybullet_quietly

import_pybullet_quietly()  # the wrapper and the replay import the simulator's ground truth

from trade_gym.recording.format import FORMAT_VERSION, FrameRecord, FrameTruth, SequenceError, VehicleTruth  # noqa: E402
from trade_gym.recording.wrapper import RecordSequence  # noqa: E402
from trade_gym.recording.writer import SequenceMeta, SequenceWriter  # noqa: E402

__all__ = ["FORMAT_VERSION", "FrameRecord", "FrameTruth", "RecordSequence", "SequenceError", "SequenceMeta",
           "SequenceWriter", "VehicleTruth"]
