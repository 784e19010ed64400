"""What every step shares: camera geometry, the frame record and typed scene inputs, colour (sRGB <-> linear, HDR
I/O), strict configs, seeded randomness, COCO output and pictures for people."""
