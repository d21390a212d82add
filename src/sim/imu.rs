//! Synthetic raw inertial sensors for a simulated walk (being written).
