//! Quality-control measurements on reconstructed data: height maps, profiles,
//! levelling, step height, coplanarity. Pure computation over engine types.
