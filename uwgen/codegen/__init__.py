"""Codec IR and the jinja2 generator that writes generated/."""
