"""Layer 6, inverse problems with optimistix: film parameters from patch radiances
(`film_fit`, its starts and bounds in `options`) and thickness maps from images
(`thickness_map`). Imports the layers below."""
