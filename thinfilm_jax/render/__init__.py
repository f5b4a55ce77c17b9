"""Layer 8 (after `interop`, before `cli`): what users run to see a film, beyond the library's
functions. One concern per module:

* `figure7` — Figure 7 of Kneiphof et al. 2019 (``thinfilm-jax figure7``, ``make figure7``).
* `scene` — one's own film or stack on a sphere, and a soap bubble (``thinfilm-jax render``).
* `study_scenes` — the sphere renders of Kneiphof et al. 2019, Figures 3–6, and the car
  paints (``thinfilm-jax render --scene fig4|fig3|varying|carpaint``).
* `plot` — figures on matplotlib's Agg canvas without pyplot's global state; matplotlib is
  the optional ``[plots]`` extra, imported when a figure is drawn.

Nothing in the layers below imports this package. The research studies and benchmarks that
measure the library are not part of it: they live in the repository's ``benchmarks/`` folder
(``python -m benchmarks.bench`` from a clone).
"""

from .bubble import bubble_thickness, bubble_paths, bubble_factors
from .figure7 import (
    METHOD_ORDER,
    ROWS,
    Figure7Config,
    grids,
    row_inputs,
    patch_block,
    compute_figure7,
    error_summary,
    render_figure7,
    render_error,
    run_figure7,
)
from .plot import figure, subplots, close, get_cmap
from .scene import (
    OWN_SCENES,
    pinhole,
    hit_sphere,
    exposure_of,
    write_exr,
    plot_panels,
    SceneConfig,
    shade_bubble,
    default_out_dir,
    render_scene,
    throughput_label,
    format_summary,
    config_from_dict,
)
from .scene_material import (
    make_material,
    describe,
    check_methods,
    index_json,
    index_from_json,
    material_json,
    material_from_json,
)
from .study_scenes import (
    PAINT_TABLE,
    PAINT_METHODS,
    FILM_MAP_METHODS,
    envmap_methods,
    DEFAULT_METHODS,
    RenderConfig,
    camera,
    sphere,
    thickness_field,
    map_label,
    scene_setups,
    view_azimuth,
    shade_block,
    method_map,
    render_one,
    summarise,
    summary_table,
    PANEL_DPI,
    panel_inches,
    fit_title,
    run_render,
)

__all__ = [
    "bubble_thickness",
    "bubble_paths",
    "bubble_factors",
    "METHOD_ORDER",
    "ROWS",
    "Figure7Config",
    "grids",
    "row_inputs",
    "patch_block",
    "compute_figure7",
    "error_summary",
    "render_figure7",
    "render_error",
    "run_figure7",
    "figure",
    "subplots",
    "close",
    "get_cmap",
    "OWN_SCENES",
    "pinhole",
    "hit_sphere",
    "exposure_of",
    "write_exr",
    "plot_panels",
    "SceneConfig",
    "shade_bubble",
    "default_out_dir",
    "render_scene",
    "throughput_label",
    "format_summary",
    "config_from_dict",
    "make_material",
    "describe",
    "check_methods",
    "index_json",
    "index_from_json",
    "material_json",
    "material_from_json",
    "PAINT_TABLE",
    "PAINT_METHODS",
    "FILM_MAP_METHODS",
    "envmap_methods",
    "DEFAULT_METHODS",
    "RenderConfig",
    "camera",
    "sphere",
    "thickness_field",
    "map_label",
    "scene_setups",
    "view_azimuth",
    "shade_block",
    "method_map",
    "render_one",
    "summarise",
    "summary_table",
    "PANEL_DPI",
    "panel_inches",
    "fit_title",
    "run_render",
]
