//! Sensing: lidar ray casting, tactile forces, odometry, beacons, position fix
