"""Tests of the manifest loader."""
