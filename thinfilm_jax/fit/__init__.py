"""Layer 6, inverse problems: film parameters from patch radiances (`film_fit`, its starts
and bounds in `options`) and thickness maps from images (`thickness_map`), on one fitting
engine (`engine`: box transform, Levenberg–Marquardt, covariance; optimistix's other
solvers by name). Imports the layers below."""
