"""Weather: fog, rain and snow from scattering physics (see docs/WEATHER.md)."""
