"""Boards found without the chessboard grid search: Kalibr's AprilGrid (tags decoded, corners by the
saddle fit) and circle grids (blob centres corrected for blur).
"""
