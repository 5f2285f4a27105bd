"""From odometry and loop closures to a corrected trajectory, and its error measured as the field does.

``trajectory``  SE(3) helpers on (N, 4, 4) float64 poses, writing a TUM file, and the one
                wheel-odometry drift model (``datasets.odometry.simulate_odometry``) on SE(3) poses
                (``drift_poses``); odometry is read by ``datasets.odometry.read_odometry``
``posegraph``   the pose graph (GTSAM): odometry between-factors and loop factors, optimised with
                plain Levenberg-Marquardt, GNC-TLS (odometry as known inliers) or a robust kernel;
                false loops injected for the robustness curve
``metrics``     ATE after SE(3) Umeyama alignment, the end-point error, RPE (evo's definitions,
                written here: evo is GPL-3.0), timestamp association, a top-down trajectory plot
``slam``        ``python -m greenloop slam``'s work: odometry (a bag's topic, TUM, KITTI) given to each
                frame by ``datasets.odometry.associate``, and a closures CSV in, the
                corrected TUM trajectory and each loop factor's weight out, errors against the
                recording's ground truth

Poses everywhere are camera-to-world (or body-to-world) homogeneous matrices, metres and radians,
as ``greenloop.datasets.sequence.read_trajectory`` returns them.
"""
