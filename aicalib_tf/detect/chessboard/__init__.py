"""Chessboards: refined corners -> grids (seeds, growth, holes) -> local lattice fits -> OpenCV's board
order, or a partial board placed on the pattern; a second look at thin boards (``zoom``).
"""
