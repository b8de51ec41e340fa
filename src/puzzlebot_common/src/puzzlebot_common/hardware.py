"""The lab's robots and set-up: the limits and rates more than one package uses, each defined once.

The robot's dimensions live in :class:`puzzlebot_common.geometry.RobotGeometry`;
this module holds its limits and the set-up's rates (facts.md, "Control" and
"Lab hardware"). The other packages take their defaults from here:

============== ============================================================================
value          read by
============== ============================================================================
V_MAX, W_MAX   MPCSettings.hardware_v_max / hardware_w_max (open-loop commands stay within);
               DriverParams.v_limit / w_limit (faster commands are rejected)
MPS_PER_PWM    MotorParams.mps_per_pwm (the emulated motors)
CONTROL_PERIOD MPCSettings.dt (the MPC's period and Euler step);
               SimParams.sync_period (the simulation's lockstep with the MPC)
MOCAP_RATE     SimParams.pose_rate, EmulatorParams.pose_rate (poses published at the Vicon's rate)
============== ============================================================================

A node's YAML file may override any of them for that node alone;
``puzzlebot_bringup/test/test_config_agreement.py`` fails when the shipped
configuration of two nodes disagrees on one of them.
"""

#: m/s, the robots' top speed (hardware limit; the simulated wheels' rim speed at their speed limit)
V_MAX = 0.2
#: rad/s, the robots' top turn rate (hardware limit)
W_MAX = 6.0
#: m/s of wheel rim speed per PWM unit, nominal (the lab's figure: 1/0.0007 PWM per m/s)
MPS_PER_PWM = 0.0007
#: s, the MPC's control period and Euler step (paper: dt = 0.1 s, the MPC at 10 Hz)
CONTROL_PERIOD = 0.1
#: Hz, the lab's Vicon rate: the simulation and the emulator publish poses at it
MOCAP_RATE = 100
