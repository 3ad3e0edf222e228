"""Body-mounted pinhole camera rendered by pybullet: RGB, metric depth and body-id segmentation.

Owns the mount (T_body_cam), the OpenGL projection built from the intrinsics and the depth linearisation.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade.camera_pitch import mount_rotation
from trade.geometry import CameraIntrinsics, Pose
from trade_gym.sim.mesh_files import draw_meshes_from_files

FloatArray = npt.NDArray[np.float64]

RENDERERS = ("tiny", "egl")
MODALITIES = ("rgb", "thermal")  # what the camera images: visible light, or long-wave infrared (`thermal_camera`)
# Where each renderer samples pixel (u, v) (OpenCV, row 0 on top): NDC x = 2 (u + du) / W - 1,
# NDC y = 1 - 2 (v + dv) / H. Measured by rendering markers at known points (tests check < 0.5 px):
# TinyRenderer samples at integer window coordinates and flips rows as H - 1 - y; OpenGL at centres.
_PIXEL_SAMPLE_OFFSET_PX = {"tiny": (0.0, 1.0), "egl": (0.5, 0.5)}
_RENDERER_FLAGS = {"tiny": p.ER_TINY_RENDERER, "egl": p.ER_BULLET_HARDWARE_OPENGL}
_GL_FROM_CV = np.diag([1.0, -1.0, -1.0])  # OpenGL eye axes (x right, y up, z back) in OpenCV axes


@dataclass(frozen=True)
class Lighting:
    """The light getCameraImage shades with: direction towards the light (world, need not be unit), colour (r, g, b)
    in [0, 1] and the ambient, diffuse and specular coefficients of pybullet's shading."""

    direction_world: tuple[float, float, float]
    colour_rgb: tuple[float, float, float]
    ambient: float
    diffuse: float
    specular: float

    def bullet_kwargs(self) -> dict[str, object]:
        return {"lightDirection": list(self.direction_world), "lightColor": list(self.colour_rgb),
                "lightAmbientCoeff": self.ambient, "lightDiffuseCoeff": self.diffuse,
                "lightSpecularCoeff": self.specular}


# pybullet's own light in a z-up world, used when getCameraImage is given none (measured: rendering with these
# gives the same bytes as rendering without; passing some of them alone does not)
DEFAULT_LIGHTING = Lighting((-50.0, 30.0, 100.0), (1.0, 1.0, 1.0), 0.6, 0.35, 0.05)


@dataclass(frozen=True)
class CameraConfig:
    """Image size, vertical field of view, mount pitch (90 = straight down), clip planes and modality (MODALITIES; the
    render is the same, `appearance.EpisodeLook` makes a thermal image of it)."""

    width_px: int = 256
    height_px: int = 256
    fov_deg: float = 110.0  # vertical, as pybullet/OpenGL
    pitch_deg: float = 90.0  # optical axis below the body x axis
    near_m: float = 0.1
    far_m: float = 1000.0
    renderer: str = "tiny"
    mount_offset_body_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # inside the airframe box
    shadows: bool = False
    modality: str = "rgb"

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if int(value) != value or value <= 0:
                raise ValueError(f"CameraConfig.{name} must be a positive integer, got {value!r}")
        if not 0.0 < self.fov_deg < 180.0:
            raise ValueError(f"CameraConfig.fov_deg must be in (0, 180), got {self.fov_deg!r}")
        if not 0.0 <= self.pitch_deg <= 90.0:
            raise ValueError(f"CameraConfig.pitch_deg must be in [0, 90], got {self.pitch_deg!r}")
        if not (math.isfinite(self.near_m) and self.near_m > 0):
            raise ValueError(f"CameraConfig.near_m must be finite and > 0, got {self.near_m!r}")
        if not (math.isfinite(self.far_m) and self.far_m > self.near_m):
            raise ValueError(f"CameraConfig.far_m must be finite and > near_m, got {self.far_m!r}")
        if self.renderer not in RENDERERS:
            raise ValueError(f"CameraConfig.renderer must be one of {RENDERERS}, got {self.renderer!r}")
        if self.modality not in MODALITIES:
            raise ValueError(f"CameraConfig.modality must be one of {MODALITIES}, got {self.modality!r}")
        offset = self.mount_offset_body_m
        if len(offset) != 3 or not all(math.isfinite(v) for v in offset):
            raise ValueError(f"CameraConfig.mount_offset_body_m must be three finite values, got {offset!r}")


@dataclass(frozen=True)
class CameraFrame:
    """One rendered image: rgb (H, W, 3) uint8; depth_m (H, W) float32 camera-frame z [m] (far_m where
    nothing was hit); seg (H, W) int32 pybullet body unique ids (-1 = none); the pose it was taken from."""

    rgb: npt.NDArray[np.uint8]
    depth_m: npt.NDArray[np.float32]
    seg: npt.NDArray[np.int32]
    T_world_cam: Pose
    intrinsics: CameraIntrinsics


def projection_matrix(K: CameraIntrinsics, near_m: float, far_m: float, renderer: str) -> list[float]:
    """OpenGL projection (column-major 16 floats) that renders pixel (u, v) exactly where K projects."""
    du, dv = _PIXEL_SAMPLE_OFFSET_PX[renderer]
    w, h = K.width_px, K.height_px
    P = np.zeros((4, 4))
    # x_ndc = (2 fx / W) x_e / -z_e + (2 (cx + du) / W - 1); y_ndc likewise with the row flip
    P[0, 0] = 2.0 * K.fx_px / w
    P[0, 2] = 1.0 - 2.0 * (K.cx_px + du) / w
    P[1, 1] = 2.0 * K.fy_px / h
    P[1, 2] = 2.0 * (K.cy_px + dv) / h - 1.0
    # standard OpenGL depth: z_ndc = ((f + n) z_e + 2 f n) / ((n - f) (-z_e))
    P[2, 2] = -(far_m + near_m) / (far_m - near_m)
    P[2, 3] = -2.0 * far_m * near_m / (far_m - near_m)
    P[3, 2] = -1.0
    return P.flatten(order="F").tolist()


def view_matrix(T_world_cam: Pose) -> list[float]:
    """OpenGL view matrix (column-major 16 floats) = inverse of T_world_glcam."""
    R_world_gl = T_world_cam.R @ _GL_FROM_CV
    V = np.eye(4)
    V[:3, :3] = R_world_gl.T
    V[:3, 3] = -R_world_gl.T @ T_world_cam.t
    return V.flatten(order="F").tolist()


class Camera:
    """Renders the pybullet scene of `client_id` from a pose; the projection is fixed at construction.

    With renderer "egl" the EGL plugin is loaded into the client here (it then serves every render of
    that client and survives resetSimulation) and the client's meshes are built from OBJ files from now on
    (`trade_gym.sim.mesh_files`: the plugin draws no in-memory mesh); call `close()` to unload it. Memory, measured
    over 30 env resets at 64 px (RSS, desert): TinyRenderer ~0 MB per reset; EGL +0.3-0.5 MB per reset of one world
    (world_seed fixed) and +4 MB per world never built before in the process (the plugin's own cache of the OBJ files
    it read; it was +16 MB before Bullet's cache was turned off here). Unloading the plugin before resetSimulation and
    reloading it after is no way out: loading it again into a client segfaults (pybullet 3.2.7).
    """

    def __init__(self, client_id: int, config: CameraConfig | None = None) -> None:
        self.client_id = int(client_id)
        self.config = config if config is not None else CameraConfig()
        cfg = self.config
        self.intrinsics = CameraIntrinsics.from_fov(cfg.width_px, cfg.height_px, cfg.fov_deg)
        self.T_body_cam = Pose(mount_rotation(cfg.pitch_deg), np.asarray(cfg.mount_offset_body_m))
        self._projection = projection_matrix(self.intrinsics, cfg.near_m, cfg.far_m, cfg.renderer)
        self._plugin_id = _load_egl_plugin(self.client_id) if cfg.renderer == "egl" else None
        if self._plugin_id is not None:
            draw_meshes_from_files(self.client_id, True)
            # Bullet's OBJ cache (process-wide) would keep every world's meshes: 15 -> 4 MB RSS per new desert world
            p.setPhysicsEngineParameter(enableFileCaching=0, physicsClientId=self.client_id)
        self._renderer_flag = _RENDERER_FLAGS[cfg.renderer]

    def pose(self, R_world_body: npt.ArrayLike, position_m: npt.ArrayLike) -> Pose:
        """T_world_cam from the body attitude (3, 3) and position (3,) world [m]."""
        R = np.asarray(R_world_body, dtype=np.float64)
        t = np.asarray(position_m, dtype=np.float64)
        # T_world_cam = T_world_body T_body_cam: R_wc = R_wb R_bc, t_wc = R_wb t_bc + t_wb
        return Pose.unchecked(R @ self.T_body_cam.R, R @ self.T_body_cam.t + t)

    def render(self, T_world_cam: Pose, lighting: Lighting | None = None) -> CameraFrame:
        """Render RGB, camera-frame z depth [m] and body-id segmentation from `T_world_cam`, lit by `lighting`
        (None: pybullet's own light, `DEFAULT_LIGHTING`)."""
        cfg = self.config
        w, h = cfg.width_px, cfg.height_px
        light = {} if lighting is None else lighting.bullet_kwargs()
        # default flags: the segmentation buffer holds body unique ids (no link index packed in)
        _, _, rgba, depth_buffer, seg = p.getCameraImage(
            w, h, view_matrix(T_world_cam), self._projection, shadow=int(cfg.shadows),
            renderer=self._renderer_flag, physicsClientId=self.client_id, **light,
        )
        rgb = np.ascontiguousarray(np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3])
        d = np.asarray(depth_buffer, dtype=np.float64).reshape(h, w)
        # window depth d in [0, 1] -> eye z: z = f n / (f - (f - n) d), in float64 (cancellation near f)
        n, f = cfg.near_m, cfg.far_m
        depth_m = ((f * n) / (f - (f - n) * d)).astype(np.float32)
        seg_ids = np.asarray(seg, dtype=np.int32).reshape(h, w)
        return CameraFrame(rgb, depth_m, seg_ids, T_world_cam, self.intrinsics)

    def close(self) -> None:
        """Unload the EGL plugin if this camera loaded it; safe to call twice."""
        if self._plugin_id is not None:
            if p.isConnected(physicsClientId=self.client_id):
                p.unloadPlugin(self._plugin_id, physicsClientId=self.client_id)
            draw_meshes_from_files(self.client_id, False)
            self._plugin_id = None


def _load_egl_plugin(client_id: int) -> int:
    """Load pybullet's EGL renderer plugin into `client_id`; raises RuntimeError if unavailable."""
    spec = importlib.util.find_spec("eglRenderer")
    plugin_id = -1
    if spec is not None and spec.origin is not None:
        plugin_id = p.loadPlugin(spec.origin, "_eglRendererPlugin", physicsClientId=client_id)
    if plugin_id < 0:
        raise RuntimeError(f"renderer 'egl' unavailable (eglRenderer plugin load returned {plugin_id}); "
                           "use renderer='tiny'")
    return plugin_id
