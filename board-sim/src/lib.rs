//! board-sim: runs one firmware runtime per board image on host threads over emulated links.
//! (The runtime and the emulated links arrive with the board-runtime issue.)
