"""The robot's hardware around the physics step: what its sensors read (`signals`: IMU, odometry, foot
contact; `sensor_noise`: each instance's noise, bias and delay line), what its motors make of a command
(`actuators`: ideal or a DC motor's torque-speed line, and the action delay), and the shoves it receives
(`pushes`)."""
