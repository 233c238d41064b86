//! Planning: APF, DWA, random walk, bounce-back, frontier selection (seed §1, §3-§5)
