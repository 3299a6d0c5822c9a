/* The uniform block shared by every Nubis shader. Python packs it by parsing this struct
 * (render/uniforms.py), so a field added here must also be filled there. Only vec4 members:
 * std140 then needs no padding rules. Units are metres, seconds and radiance. */
#define NUBIS_MAX_STORMS 4

struct NubisParams {
  vec4 layer;      /* planet radius, layer bottom altitude, layer top altitude, draw radius */
  vec4 shell;      /* lowest and highest altitude any cloud can reach (the field's min/max heights), -, - */
  vec4 field;      /* field centre x, y, field size, 1 / field size */
  vec4 draw;       /* draw centre x, y (the camera), fade width at the draw radius, - */
  vec4 noise;      /* LF period, HF period, curl period, curl displacement */
  vec4 wind;       /* wind direction x, y, distance travelled (speed * time), detail speed factor */
  vec4 wind2;      /* cloud-top offset, upward bias, time in seconds, - */
  vec4 density;    /* extinction per metre, coverage multiplier, erosion strength, multiply by coverage (0/1) */
  vec4 sun_dir;    /* unit vector towards the sun, - */
  vec4 sun_rad;    /* sun colour * strength (irradiance), - */
  vec4 ambient;    /* sky light from above (the World's cosine-weighted radiance) * strength, ambient at the
                    * base relative to the top */
  vec4 ambient_below; /* sky light from below (the ground) * strength, the strength alone */
  vec4 phase;      /* g0, g1, weight of lobe 1, rain absorption multiplier */
  vec4 march;      /* view steps looking up, view steps to the horizon, light step length, light taps */
  vec4 scatter;    /* multiple-scattering octaves, attenuation a, contribution b, eccentricity scale c */
  vec4 scatter2;   /* powder strength, fade distance (0 = off), -, - */
  vec4 cirrus;     /* altitude, coverage multiplier, 1 / texture period, optical depth at density 1 */
  vec4 cirrus2;    /* scroll offset x, y (metres), bake slab thickness, - */
  vec4 storm_info;          /* number of storms (<= NUBIS_MAX_STORMS), ring twist, glow height, anvil shift */
  vec4 storm_shape[4];      /* per storm: centre x, y, radius, blend factor */
  vec4 storm_light[4];      /* per storm: spin (rad/s at the centre), darkening, glow intensity, ambient boost */
  vec4 storm_glow[4];       /* per storm: glow colour rgb, flash intensity */
  vec4 storm_flash[4];      /* per storm: flash offset x, y from the centre, ground discharge (0/1),
                             * its vortex time (seconds, wrapped for float precision) */
  vec4 motion;              /* timestep of the motion vectors in seconds, wind speed (m/s), -, - */
  vec4 clip_box;   /* x0, y0, x1, y1: no clouds outside (a comparison clips to the baked box); x1 < x0: off */
  vec4 options;    /* jitter (0/1), jittered storm rings (0/1), accumulation pass, - */
  vec4 view;       /* pixel footprint: metres per metre of distance, metres (orthographic), base mip,
                    * most view steps within the shader loop limit */
  vec4 light_taps[16]; /* the light march's taps (core/march.py): offset from the point, length it stands for */
};

/* The temporal resolve's inputs (render/temporal.py), one block per redraw. */
struct NubisTemporal {
  mat4 inv_view_proj;  /* this redraw's camera, as the march's rays */
  mat4 prev_view_proj; /* the camera of the previous redraw */
  vec4 eye;            /* this redraw's eye (w = 1: perspective) */
  vec4 size;           /* history width, height, working-buffer width, height */
  vec4 frame;          /* Bayer index marched now, redraws since the last change, weight of the new sample, dt */
  vec4 flags;          /* history valid (0/1), -, the pixel of each 4x4 block marched now (x, y) */
};

/* The motion stage's cameras: now and one timestep earlier (the same for a still camera). */
struct NubisMotionCameras {
  mat4 view_proj;
  mat4 prev_view_proj;
};
