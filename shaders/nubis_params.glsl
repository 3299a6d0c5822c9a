/* Declarations shared by every Nubis shader. The NubisParams uniform block itself, one member per
 * setting named after its key (P.lighting_powder), is generated from core/schema.py by
 * render/uniforms.py and declared ahead of this file. Units are meters, seconds and radiance. */
/* The temporal resolve's inputs (render/temporal.py), one block per redraw. */
struct NubisTemporal {
  mat4 inv_view_proj;  /* this redraw's camera, as the march's rays */
  mat4 prev_view_proj; /* the camera of the previous redraw */
  vec4 eye;            /* this redraw's eye (w = 1: perspective) */
  vec4 size;           /* history width, height, working-buffer width, height */
  vec4 frame;          /* Bayer index marched now, redraws since the last change, weight of the new sample, dt */
  vec4 flags;          /* history valid (0/1), -, the pixel of each 4x4 block marched now (x, y) */
  vec4 scene;          /* a scene depth bound (0/1), view pixels per history pixel (x, y), - */
  vec4 depth_map;      /* the view's projection of its depth (nubis_axial_depth) */
  vec4 view_axis;      /* this redraw's axis (nubis_axial_to_ray) */
  vec4 prev_axis;      /* the previous redraw's */
};

/* The motion stage's cameras: now and one timestep earlier (the same for a still camera). */
struct NubisMotionCameras {
  mat4 view_proj;
  mat4 prev_view_proj;
};
