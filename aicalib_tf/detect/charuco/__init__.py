"""ChArUco boards: markers read -> the chessboard lattice without the markers' own junctions -> named
by the markers, completed, grown and refined.
"""
