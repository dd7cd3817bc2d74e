"""Hand-eye calibration: robot poses + board views -> PnP -> rotation spread -> robust closed-form start
-> joint fit -> outlier views -> the transform, its sigma, files and report.
"""
