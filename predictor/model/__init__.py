"""The gripper's physics: the joint model, the finger chain and its equilibrium residual
(floor 1 of predictor).

* ``joint``: ``JointModel`` (``AnalyticJoint``, ``SurrogateJoint``: the torch surrogate of
  surrogate/), ``load_joint``, ``check_finger``: a joint's anchors, cap and exit angle for
  (P, tau);
* ``gripper``: the finger chain of a finger file (``GripperParams``, ``ChainLayout``), its
  weights, forward kinematics (``finger_pose``, Equation 3) and outline;
* ``statics``: Equation 1, the equilibrium residual with gravity, the object's and the
  plane X = 0's contact (``GripperProblem``, ``Obstacle``, ``ContactParams``, grasp states);
* ``plot``: matplotlib drawing of a gesture (the finger chain's outline, the paper's colours).

Imports: contract, surrogate, predictor.defaults (no other predictor sub-package).
"""
