"""Rigs of cameras: each camera as one -> placement from shared frames -> one joint fit of every lens and
pose -> rectified |dy|, baseline and rotation sigma, sanity -> stereo YAML, camera_info, rig.json, Kalibr.
"""
