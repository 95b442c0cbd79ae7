//! The kitchen twin: scene loading, physics, robot, sensors, success checks and monitors. No networking.
