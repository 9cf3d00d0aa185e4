"""ROS-free simulator of the MMAUD rig: scenes, Livox scan models, drones, distractors."""
