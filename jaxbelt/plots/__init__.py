"""Matplotlib figures: the papers' figures and more. One module per scene."""
