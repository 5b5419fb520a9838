"""Tests of the .msg/.srv parser and the interface library."""
