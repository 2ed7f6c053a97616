"""
Control laws for closing a loop around the stage (pure Python, no ROS).

The example controller node `flexure_sim.node.apps.pi_controller` is a thin shell around
`pi_notch`.
"""
