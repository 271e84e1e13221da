"""Command shaping on the user's own axis: residuals, classic shapers, the convex minimax design, the plan.

The public names are re-exported by `jaxbelt` itself (`jb.design_move`, `jb.identify_axis`, ...).
"""
