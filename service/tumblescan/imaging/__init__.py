"""Shared imaging for the optical kinds: a pinhole camera, a ray-cast renderer of triangle meshes,
a sensor model (PSF, shot and read noise, sky, stars, quantization), image files and line helpers.

Conventions (see docs/imaging.md): the camera frame is OpenCV's (x right, y down, z forward);
pixel centres sit at integer coordinates, so pixel (u, v) covers [u-0.5, u+0.5] x [v-0.5, v+0.5]
and the image spans [-0.5, width-0.5]; lengths are metres, angles radians unless a name says
``_deg``. Heavy libraries (cv2, open3d, scipy) are imported inside the functions that use them.
"""
