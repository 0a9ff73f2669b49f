"""Exchange with the world outside fivecal: controllers (``linuxcnc``)."""
