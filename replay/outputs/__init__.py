"""Outputs of an evaluation: leaderboard and estimate files, the HTML report, MCAP and ROS 2 exports."""
