//! Localization: histogram Bayes filter, KF, EKF, PF (seed §6)
