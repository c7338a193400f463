"""A LiDAR 1 m above a Lambertian floor (ρ = 0.5 at every wavelength), two rings at -10° and
-30°, 36 columns 10° apart, ``compensated`` mode: every beam returns, ring r at range
``1 / sin(-θ_r)`` with ``cos θ = sin(-θ_r)`` (the closed form of the per-laser tests)."""

#: The two rings' elevations, degrees.
ELEV = (-10.0, -30.0)


def floor_scene(params: str, gain: float = 1.0) -> str:
    """The scene's XML body with the sensor's extra ``params`` (XML elements) and ``gain``."""
    return f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="{",".join(map(str, ELEV))}"/>
        <integer name="horizontal_resolution" value="36"/>
        <float name="gain" value="{gain:g}"/>
        <string name="intensity_mode" value="compensated"/>
        <float name="range_min" value="0.1"/>
        {params}
        <transform name="to_world"><translate z="1"/></transform>
    </sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf>
    <shape type="rectangle"><transform name="to_world"><scale value="50"/></transform>
        <ref id="grey"/></shape>
    """
