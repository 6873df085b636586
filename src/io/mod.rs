//! Reading and writing formats: fringe-set manifests, images, calibration,
//! point clouds, maps. May use `engine` types; never the GUI.
