"""VXGI: voxel cone tracing (Crassin et al. 2011), indirect diffuse, glossy and AO added to DIRECT.

Passes: DIRECT's (gbuffer, light_cull, shadows, direct_light) → ``rsm`` (passes/rsm.py: the
suns' shadow maps over the whole scene) → ``vxgi_voxelize`` (conservative, cascades centred on
the camera; the records are kept while the surfaces and the cascades stay put) → ``vxgi_inject`` (direct light from the shadow maps,
optional multi-bounce from last frame's volume; anisotropic mips) → ``vxgi_trace`` (6
diffuse cones + 1 specular cone per pixel, composited into the colour) → ``vxgi_debug``
(GI_VXGI_Voxels). Compared with Cycles "full" (multi-bounce on). See passes/vxgi.py and
docs/techniques/VXGI.md.

| parameter | pass | range | meaning |
|---|---|---|---|
| resolution | vxgi_voxelize | 8–256 | voxels per side of one cascade |
| cascades | vxgi_voxelize | 1–4 | cascades (voxel size doubles) |
| voxel_size | vxgi_voxelize | 0–100 | finest voxel size (0: the coarsest cascade holds the scene) |
| thickness | vxgi_voxelize | 0–2 | dilation in voxels (thicker voxelisation, against leaks) |
| multi_bounce | vxgi_inject | bool | inject last frame's indirect irradiance and sky light |
| step | inject, trace | 0.1–2 | cone step, fraction of the cone diameter |
| normal_offset | inject, trace | 0–4 | cones start this many voxels off the surface |
| opacity_scale | inject, trace | 1–4 | opacity bias (against leaks) |
| edge_opacity | vxgi_inject | 0–1 | smallest level-0 opacity of an occupied voxel (edge-on surfaces occlude; 0.1) |
| footprint_cap | inject, trace | 0–4 | diffuse cone footprint <= this x the height over the receiver's plane (0.35) |
| audit_radiance | inject, trace | 0–1e3 | energy audit: every voxel side shows this radiance, GI_IndirectDiffuse = E/π |
| max_distance | inject, trace | 0–1e4 | cone length (0: the coarsest cascade's side) |
| light_cull, cull_fraction, cull_samples | vxgi_inject | bool, 0–1, 0–32 | many lights (>= 32): a voxel shades the lights whose range holds it, the rest by power-sampled lights (unbiased; 0.05, 4) |
| specular, min_aperture | vxgi_trace | | the specular cone and its narrowest aperture |
| mip | vxgi_debug | 0–8 | mip level shown by GI_VXGI_Voxels |

Accuracy (64 px, Cycles full, 4 frames): Cornell mean 0.97 / 1.01 / 0.91 / 0.87 of Cycles' at
q0-q3, relMSE 0.062 / 0.060 / 0.048 / 0.044 (DIRECT 0.278); sun-lit room relMSE 0.081 / 0.038 /
0.024 / 0.024 (DIRECT 0.084). Each directional face is read as a box along its own axis and a
sample's radiance weights its faces by opacity, which keeps walls opaque and bright at the cost
of a small thin-wall leak; box_ramp 0.5 (a ramp across texel boundaries) keeps cone samples
continuous under motion; a moving cascade is read at mips 0-2 only, so its 4-voxel snap does
not shift the coarser mips. The largest frame-to-frame steps left sit on G-buffer edges. Energy audit
(closed-box furnace, ideal 1): 0.69 at the defaults, 0.87 with edge opacity 0
(docs/techniques/VXGI.md).

Many lights: a reset frame computes the direct light once (its later bounce runs load it), and
the injection culls lights per voxel with DIRECT's ranges (many_lights q0: 2.0 s per frame
instead of 6.4).

Quality ladder (voxels per side of each of 2 cascades; bounce iterations within the frame after
a history reset, ``reset_bounces``): 0 = 32³ (6); 1 = 48³ (6); 2 = 64³ (8); 3 = 96³ (8). No
warm-up frames: the first frame is converged (the F12 warm-up, the viewport and animations alike).
"""
from __future__ import annotations

from ..passes.gbuffer import GBufferPass
from ..passes.light_cull import LightCullPass
from ..passes.rsm import RSMPass
from ..passes.shadows import ShadowPass
from ..passes.vxgi import (AO, DEBUG, DIFFUSE, GLOSSY, VoxelDebugPass, VoxelInjectPass, VoxelizePass, VoxelMipPass,
                           VoxelTracePass, VXGIGraph)
from . import Technique, register
from .direct import DIRECT_OUTPUTS, DirectLightPass


def vxgi_passes(quality) -> list:
    vox = VoxelizePass(quality)
    inject = VoxelInjectPass(quality, voxelize=vox)
    return [vox, inject, VoxelMipPass(quality), VoxelTracePass(quality, inject=inject), VoxelDebugPass(quality)]


class VXGI(Technique):
    id = "VXGI"
    label = "VXGI"
    description = ("Voxel cone tracing: the scene voxelised (again only when it moves), lit from the shadow maps, "
                   "6 diffuse + 1 specular cone per pixel, added to DIRECT")
    family = "raster3d"
    reference = "full"
    cost_rank = 30
    converges = True
    # no warm-up frames: after a history reset the injection runs `reset_bounces` (6/6/8/8)
    # bounce iterations within the frame, so the first frame (F12, viewport, animation) is
    # already converged (before: 4/6/8/8 warm-up frames, one bounce more per frame)
    warmup_frames = 0
    outputs = {**DIRECT_OUTPUTS, "GI_IndirectDiffuse": DIFFUSE, "GI_IndirectGlossy": GLOSSY, "GI_AO": AO,
               "GI_VXGI_Voxels": DEBUG}

    def passes(self, quality):
        return [GBufferPass(quality), LightCullPass(quality), ShadowPass(quality), DirectLightPass(quality),
                # the RSM views of the lights only, read as their shadow maps: the world
                # reaches the voxels through their cones instead
                RSMPass(quality, world_directions=0), *vxgi_passes(quality)]

    graph_class = VXGIGraph


register(VXGI)
