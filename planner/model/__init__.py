"""What is planned with: the robot and its hands, the task, the environment, the object's mesh and generated shapes."""
