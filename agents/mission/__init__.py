"""The quadrotor mission: discrete policies flying robots with dynamics (:mod:`.flight`)."""
