"""The thermal scene: surface temperatures over a clear day from the sun, the air and each material's heat storage,
and the radiance temperature a downward LWIR camera sees of each pixel.

Owns `ThermalLook` (one episode's time of day, air, wind and emissivities), `draw_thermal_look`, `Material`,
`MATERIALS`, the sun and air of a time of day (`SunAndAir`) and `SurfaceModel` (per-pixel temperatures).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]

STEFAN_BOLTZMANN_W_M2K4 = 5.670374419e-8  # CODATA 2018
HOURS_PER_DAY = 24.0
SECONDS_PER_HOUR = 3600.0
DAY_SAMPLES = 288  # the day cycle is solved on this many times (5 min apart), then interpolated
# Sun: clear sky at the equinox (declination 0: sunrise 6 h, sunset 18 h, solar time = clock time) at the latitude
# of JPL, Pasadena, where TRADE was flown (paper: affiliation and real-world experiments)
LATITUDE_DEG = 34.2
SOLAR_DECLINATION_DEG = 0.0
HOUR_ANGLE_DEG_PER_H = 15.0
SOLAR_NOON_H = 12.0
# Direct normal irradiance of a clear sky, Meinel & Meinel (1976) as given by PVEducation ("Air Mass"):
# E_dir = 1353 W/m^2 * 0.7^(AM^0.678), AM = 1 / sin(elevation); diffuse on a clear day ~10 % of direct (same source)
SOLAR_CONSTANT_W_M2 = 1353.0
CLEAR_SKY_TRANSMITTANCE = 0.7
AIR_MASS_EXPONENT = 0.678
DIFFUSE_FRACTION = 0.1
MIN_SUN_ELEVATION_SIN = 1e-3  # below this the sun is down (keeps the air mass finite)
# Air: T(t) = mean + amplitude cos(2 pi (t - 15 h) / 24 h); the daily maximum comes 2-3 h after solar noon, the
# minimum near sunrise (standard climatology). Mean and amplitude: a mild clear day (assumed; randomized draws them).
AIR_MEAN_K = 293.15  # 20 degC
AIR_AMPLITUDE_K = 6.0  # 12 K from dawn to afternoon
AIR_MAX_H = 15.0
WIND_MPS = 2.0  # light breeze (assumed; randomized draws it)
# Clear-sky emissivity, Swinbank (1963, QJRMS 89:339): L_sky = 5.31e-13 T_air^6 W/m^2 = eps_sky sigma T_air^4
SWINBANK_EMISSIVITY_PER_K2 = 9.365e-6
# Convective heat transfer coefficient of a surface in wind v: h = 5.7 + 3.8 v [W/(m^2 K)] (McAdams, as used in
# Duffie & Beckman, Solar Engineering of Thermal Processes)
CONVECTION_STILL_W_M2K = 5.7
CONVECTION_PER_WIND_W_M2K_PER_MPS = 3.8
LINEAR_SRGB_LUT = np.array([c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4
                            for c in np.arange(256) / 255.0], dtype=np.float32)  # IEC 61966-2-1 decoding
LUMINANCE_RGB = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)  # Rec. 709 / sRGB luminance weights
# Randomized appearance (`draw_thermal_look`): air from a cold to a hot day, its daily swing, the wind
AIR_MEAN_RANGE_K = (278.15, 308.15)  # 5-35 degC
AIR_AMPLITUDE_RANGE_K = (3.0, 9.0)  # daily range 6-18 K (humid/cloudy to desert)
WIND_RANGE_MPS = (0.5, 6.0)


@dataclass(frozen=True)
class Material:
    """A surface: its LWIR emissivity (nominal, and the range of its table entry that randomized appearance draws
    from) and how it stores heat: a semi-infinite solid of conductivity k [W/(m K)], density [kg/m^3] and specific
    heat [J/(kg K)], or, with `shell_m`, a sheet that thick (a lumped layer: k is unused)."""

    emissivity: float
    emissivity_range: tuple[float, float]
    conductivity_w_mk: float
    density_kg_m3: float
    specific_heat_j_kgk: float
    shell_m: float | None = None

    def storage_admittance(self, omega_radps: npt.NDArray[np.floating]) -> npt.NDArray[np.complexfloating]:
        """Heat flux into the material per kelvin of surface temperature at angular frequency omega [W/(m^2 K)]:
        Y = e sqrt(i omega) with effusivity e = sqrt(k rho c) (Carslaw & Jaeger, periodic surface temperature of a
        semi-infinite solid), or Y = i omega rho c d for a sheet d thick."""
        rho_c = self.density_kg_m3 * self.specific_heat_j_kgk
        if self.shell_m is not None:
            return 1j * omega_radps * rho_c * self.shell_m
        return math.sqrt(self.conductivity_w_mk * rho_c) * np.sqrt(1j * omega_radps)


# Emissivities: Incropera et al., Fundamentals of Heat and Mass Transfer, Table A.11 (total, near 300 K): sand 0.90,
# soil 0.93-0.96, concrete 0.88-0.93, asphalt pavement 0.85-0.93, rocks 0.88-0.95, ice 0.95-0.98, paints 0.90-0.98.
# Thermal properties: the same book's Tables A.1 and A.3 (sand, soil, concrete (stone mix), granite, ice, plain carbon
# steel). Asphalt streets use concrete's properties (Table A.3's asphalt conductivity, 0.062 W/(m K), is an insulating
# grade). Vehicle shells: painted steel sheet, 1 mm (car), 1.5 mm (truck), 25 mm armour (tank) (assumed).
STEEL = (60.5, 7854.0, 434.0)
MATERIALS: MappingProxyType[str, Material] = MappingProxyType({
    "sand": Material(0.90, (0.88, 0.92), 0.27, 1515.0, 800.0),
    "soil": Material(0.94, (0.93, 0.96), 0.52, 2050.0, 1840.0),
    "pavement": Material(0.90, (0.85, 0.93), 1.4, 2300.0, 880.0),
    "concrete": Material(0.91, (0.88, 0.93), 1.4, 2300.0, 880.0),
    "rock": Material(0.92, (0.88, 0.95), 2.79, 2630.0, 775.0),
    "ice": Material(0.97, (0.95, 0.98), 1.88, 920.0, 2040.0),
    "car": Material(0.93, (0.90, 0.96), *STEEL, shell_m=0.001),
    "truck": Material(0.93, (0.90, 0.96), *STEEL, shell_m=0.0015),
    "tank": Material(0.93, (0.90, 0.96), *STEEL, shell_m=0.025),
})
MATERIAL_NAMES = tuple(MATERIALS)


@dataclass(frozen=True)
class ThermalLook:
    """One episode's thermal conditions: time of day [h, 0-24, solar time], the air's daily mean and amplitude [K],
    the wind [m/s] and each material's emissivity (in MATERIAL_NAMES order)."""

    time_of_day_h: float
    air_mean_k: float = AIR_MEAN_K
    air_amplitude_k: float = AIR_AMPLITUDE_K
    wind_mps: float = WIND_MPS
    emissivity: tuple[float, ...] = tuple(m.emissivity for m in MATERIALS.values())

    def as_info(self) -> dict[str, Any]:
        """Plain floats: the draw plus the air temperature and sun elevation it gives."""
        sun = SunAndAir.of(self)
        values = asdict(self) | {"emissivity": dict(zip(MATERIAL_NAMES, self.emissivity))}
        return values | {"air_temperature_k": sun.air_k, "sun_elevation_deg": math.degrees(math.asin(sun.direction[2]))}


def draw_thermal_look(rng: np.random.Generator, time_of_day_h: float | None) -> ThermalLook:
    """Randomized conditions, drawn in a fixed order: time of day (uniform over the day unless given), the air's mean
    and swing, the wind, and each material's emissivity within its table range."""
    drawn_time = rng.uniform(0.0, HOURS_PER_DAY)
    mean, amplitude, wind = (float(rng.uniform(*r)) for r in (AIR_MEAN_RANGE_K, AIR_AMPLITUDE_RANGE_K, WIND_RANGE_MPS))
    emissivity = tuple(float(rng.uniform(*m.emissivity_range)) for m in MATERIALS.values())
    time_h = float(drawn_time) if time_of_day_h is None else float(time_of_day_h)
    return ThermalLook(time_h, mean, amplitude, wind, emissivity)


@dataclass(frozen=True)
class SunAndAir:
    """The sun and the air at one time of day: unit direction towards the sun (world: x east, y north, z up), direct
    normal and diffuse irradiance [W/m^2] (0 at night), air temperature and the clear sky's radiance temperature [K]."""

    direction: tuple[float, float, float]
    direct_w_m2: float
    diffuse_w_m2: float
    air_k: float
    sky_k: float

    @classmethod
    def of(cls, look: ThermalLook, time_h: float | None = None) -> SunAndAir:
        t = look.time_of_day_h if time_h is None else time_h
        east, north, up = sun_direction(t)
        direct = direct_irradiance_w_m2(up)
        air = air_temperature_k(look, t)
        sky = air * (SWINBANK_EMISSIVITY_PER_K2 * air**2) ** 0.25  # sigma T_sky^4 = eps_sky sigma T_air^4
        return cls((east, north, up), direct, DIFFUSE_FRACTION * direct, air, sky)


def sun_direction(time_h: float) -> tuple[float, float, float]:
    """Unit vector towards the sun (east, north, up) at solar time `time_h`: hour angle H = 15 deg/h (t - 12 h),
    s = (-cos d sin H, cos p sin d - sin p cos d cos H, sin p sin d + cos p cos d cos H), p latitude, d declination."""
    hour = math.radians(HOUR_ANGLE_DEG_PER_H * (time_h - SOLAR_NOON_H))
    lat, dec = math.radians(LATITUDE_DEG), math.radians(SOLAR_DECLINATION_DEG)
    return (-math.cos(dec) * math.sin(hour),
            math.cos(lat) * math.sin(dec) - math.sin(lat) * math.cos(dec) * math.cos(hour),
            math.sin(lat) * math.sin(dec) + math.cos(lat) * math.cos(dec) * math.cos(hour))


def direct_irradiance_w_m2(sin_elevation: float) -> float:
    """Clear-sky direct normal irradiance [W/m^2] for the sun at this sine of elevation (0 below the horizon)."""
    if sin_elevation < MIN_SUN_ELEVATION_SIN:
        return 0.0
    return SOLAR_CONSTANT_W_M2 * CLEAR_SKY_TRANSMITTANCE ** ((1.0 / sin_elevation) ** AIR_MASS_EXPONENT)


def air_temperature_k(look: ThermalLook, time_h: float) -> float:
    return look.air_mean_k + look.air_amplitude_k * math.cos(2.0 * math.pi * (time_h - AIR_MAX_H) / HOURS_PER_DAY)


@dataclass(frozen=True)
class MaterialDay:
    """A material's state at the look's time of day, for a horizontal surface: `air_k` the part of its temperature
    driven by the air's daily cycle [K]; `sun_k_per_absorptance` the part driven by the sun per unit of absorbed share
    [K]; `gain_k_per_w_m2` its response to a change of absorbed flux at the daily frequency [K/(W/m^2)];
    `exchange_w_m2k` its convective plus linearised radiative exchange coefficient h [W/(m^2 K)]."""

    air_k: float
    sun_k_per_absorptance: float
    gain_k_per_w_m2: float
    exchange_w_m2k: float


def material_day(material: Material, emissivity: float, look: ThermalLook) -> MaterialDay:
    """Solve the material's periodic day: harmonic n of the surface temperature of a horizontal surface is
    T_n = (h T_air,n + a E_h,n) / (h + Y(n w)) (Y(0) = 0: no net storage over a day), w = 2 pi / 24 h, with
    h = h_conv + 4 eps sigma T_mean^3, E_h the clear-sky global horizontal irradiance, a the absorbed share."""
    times_h = np.arange(DAY_SAMPLES) * (HOURS_PER_DAY / DAY_SAMPLES)
    air = np.array([air_temperature_k(look, t) for t in times_h])
    horizontal = np.array([_horizontal_irradiance_w_m2(t) for t in times_h])
    h = (CONVECTION_STILL_W_M2K + CONVECTION_PER_WIND_W_M2K_PER_MPS * look.wind_mps
         + 4.0 * emissivity * STEFAN_BOLTZMANN_W_M2K4 * look.air_mean_k**3)
    omega = 2.0 * math.pi * np.arange(DAY_SAMPLES // 2 + 1) / (HOURS_PER_DAY * SECONDS_PER_HOUR)
    admittance = material.storage_admittance(omega)
    at = look.time_of_day_h % HOURS_PER_DAY

    def respond(samples: FloatArray, numerator: float) -> float:
        response = np.fft.irfft(np.fft.rfft(samples) * numerator / (h + admittance), n=DAY_SAMPLES)
        return float(np.interp(at, times_h, response, period=HOURS_PER_DAY))

    gain = 1.0 / abs(h + complex(admittance[1]))
    return MaterialDay(respond(air, h), respond(horizontal, 1.0), gain, h)


def _horizontal_irradiance_w_m2(time_h: float) -> float:
    up = sun_direction(time_h)[2]
    direct = direct_irradiance_w_m2(up)
    return direct * max(up, 0.0) + DIFFUSE_FRACTION * direct


class SurfaceModel:
    """Per-pixel surface and radiance temperatures of one episode's look, for surfaces of known material, albedo and
    normal.

    Simplified (say so where it matters): broadband radiometry (radiance ~ eps T^4 over all wavelengths, not the
    8-14 um band); a surface's daily storage is solved for a horizontal surface of its material and a tilted one adds
    its extra direct and diffuse sun at the daily frequency's gain, without phase lag; the visible albedo (the unlit
    colour's luminance) stands in for the solar albedo; no cast shadows (the renderer draws none by default); no
    atmosphere between the drone and the ground (tens of metres); the conditions are the reset's for the whole
    episode (it lasts seconds to minutes of a day)."""

    def __init__(self, look: ThermalLook) -> None:
        self.look = look
        self.sun = SunAndAir.of(look)
        days = [material_day(m, e, look) for m, e in zip(MATERIALS.values(), look.emissivity)]
        self._air_k = np.array([d.air_k for d in days], dtype=np.float32)
        self._sun_k = np.array([d.sun_k_per_absorptance for d in days], dtype=np.float32)
        self._gain = np.array([d.gain_k_per_w_m2 for d in days], dtype=np.float32)
        self._exchange = np.array([d.exchange_w_m2k for d in days], dtype=np.float32)
        self._emissivity = np.array(look.emissivity, dtype=np.float32)
        # net long-wave loss of a black surface to the clear sky, linearised at the air: sigma T_air^4 (1 - eps_sky)
        self._sky_loss_w_m2 = STEFAN_BOLTZMANN_W_M2K4 * (self.sun.air_k**4 - self.sun.sky_k**4)

    def material_temperature_k(self, material: str, albedo: float = 0.0,
                               normal: tuple[float, ...] = (0.0, 0.0, 1.0)) -> float:
        """One surface's temperature [K] (for tests and docs): `surface_temperature_k` of a single pixel."""
        index = np.full((1, 1), MATERIAL_NAMES.index(material))
        normals = np.asarray(normal, dtype=np.float32).reshape(1, 1, 3)
        normals /= np.linalg.norm(normals)
        return float(self.surface_temperature_k(index, np.full((1, 1), albedo, np.float32), normals)[0, 0])

    def surface_temperature_k(self, material: npt.NDArray[np.intp], albedo: F32, normal_world: F32) -> F32:
        """(H, W) surface temperature [K] of pixels of material index `material` (H, W) (into MATERIAL_NAMES), albedo
        (H, W) in [0, 1] and unit world normal (H, W, 3):
        T = T_air,m + a (S_m + g_m (E_dir (max(0, n.s) - s_z) + E_dif (f - 1))) - eps_m L f / h_m, with a = 1 - albedo
        the absorbed share, f = (1 + n_z) / 2 the sky's share of the view, L the net long-wave loss to the sky."""
        sun = self.sun
        s = np.asarray(sun.direction, dtype=np.float32)
        cos_incidence = np.maximum(normal_world @ s, 0.0)
        sky_view = 0.5 * (1.0 + normal_world[..., 2])
        tilt_w_m2 = sun.direct_w_m2 * (cos_incidence - max(s[2], 0.0)) + sun.diffuse_w_m2 * (sky_view - 1.0)
        absorbed = 1.0 - albedo
        temperature = (self._air_k[material] + absorbed * (self._sun_k[material] + self._gain[material] * tilt_w_m2)
                       - self._emissivity[material] * self._sky_loss_w_m2 * sky_view / self._exchange[material])
        return temperature.astype(np.float32)

    def radiance_temperature_k(self, surface_k: F32, material: npt.NDArray[np.intp], normal_world: F32) -> F32:
        """(H, W) the temperature of a black body as bright as each pixel [K]: emitted plus reflected sky and
        surroundings, T_r^4 = eps T^4 + (1 - eps) (f T_sky^4 + (1 - f) T_air^4), f the sky's share of the view."""
        eps = self._emissivity[material]
        sky_view = 0.5 * (1.0 + normal_world[..., 2])
        surroundings = sky_view * self.sun.sky_k**4 + (1.0 - sky_view) * self.sun.air_k**4
        return ((eps * surface_k.astype(np.float32) ** 4 + (1.0 - eps) * surroundings) ** 0.25).astype(np.float32)


def albedo_from_unlit_rgb(rgb: npt.NDArray[np.uint8]) -> F32:
    """(H, W) albedo in [0, 1]: the relative luminance of (H, W, 3) sRGB colours rendered without shading."""
    return (LINEAR_SRGB_LUT[rgb] @ LUMINANCE_RGB).astype(np.float32)
