"""coupler_railway."""
