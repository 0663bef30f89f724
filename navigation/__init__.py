"""The second seed system: a forward camera aiding inertial navigation (MBDA EP2060873).

A low-flying vehicle without GNSS extracts 2-D line segments from its
forward-looking camera, tracks them through short image sequences
(frame-to-frame homographies), reconstructs them in 3-D from the INS relative
poses, projects them into the 2-D reference map and matches them there; the
misfit corrects the INS through an error-state Kalman filter.

Data flow (one module per step, pure NumPy / OpenCV cores):

``scenario`` → ``world`` (terrain, line map, reference map) → ``flight``
(true trajectory, IMU increments) → ``imu`` (sensor errors) → ``ins``
(strapdown mechanisation) → ``camera`` + ``simsat.render.perspective``
(frames) → ``segments`` (2-D extraction) → ``tracking`` (homographies,
tracks with virtual segments) → ``reconstruction`` (3-D lines) →
``map_matching`` (reference segments, residuals) → ``kalman`` (error-state
filter) → ``aided`` (the loop) → ``run`` (NetCDF products).

Frames: the world frame is simsat's local frame (x, y horizontal, z up,
metres) over a flat, non-rotating Earth with constant gravity: the truth and
the mechanisation share that model, so every navigation error comes from the
IMU's errors, not from a model mismatch. The body frame is x forward, y left,
z up; the camera frame is OpenCV's (x right, y down, z along the optical axis).
"""
