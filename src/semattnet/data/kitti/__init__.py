"""KITTI, by what its files are: where depth completion keeps each file (:mod:`.layout`), the splits as frames
and a torch dataset (:mod:`.splits`), raw drives read from their own files (:mod:`.raw`), what KITTI's download
server holds (:mod:`.server`), ``data download`` (:mod:`.download`) and ``data check`` (:mod:`.check`)."""

from semattnet.data.kitti.raw import RawDrive, RawFrame
from semattnet.data.kitti.splits import FrameFiles, KittiDepthCompletion, find_frames, load_frame

__all__ = ["FrameFiles", "KittiDepthCompletion", "RawDrive", "RawFrame", "find_frames", "load_frame"]
