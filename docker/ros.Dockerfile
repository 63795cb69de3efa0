# camo on the official ROS 2 Jazzy image, for users of stock ROS tools:
#   docker build -f docker/ros.Dockerfile -t camo-ros .        (from the repository root)
#   docker run --rm -it -v $PWD/bags:/bags camo-ros ros2 bag info /bags/run1
#   docker run --rm -it -v $PWD/bags:/bags camo-ros ros2 bag play /bags/run1
#   docker run --rm -it camo-ros ros2 run camo_nodes robot_node --ros-args -p rows:=8 -p cols:=8 -p row:=0 -p col:=0
# Not built here (no registry these machines reach serves ros:jazzy); camo's own image is
# docker/Dockerfile. See docs/containers.md.
FROM ros:jazzy

# rosbag2's MCAP storage, so `ros2 bag` reads the bags camo writes.
RUN apt-get update && apt-get install -y --no-install-recommends \
        ros-jazzy-rosbag2-storage-mcap python3-pip python3-yaml \
    && rm -rf /var/lib/apt/lists/*

# The algorithm's own pinned dependencies (as in requirements.txt; numpy 2 for numba and OpenCV).
RUN pip3 install --no-cache-dir --break-system-packages --ignore-installed \
        numpy==2.4.6 numba==0.68.1 opencv-python-headless==5.0.0.93 matplotlib==3.11.2 \
        mcap==1.6.0 pyserial==3.5 orjson==3.13.0

WORKDIR /ws
COPY src/ /ws/src/
RUN . /opt/ros/jazzy/setup.sh \
    && colcon build --base-paths src --event-handlers console_direct- --cmake-args -DBUILD_TESTING=OFF

# Every shell and `docker run` command sees the workspace (ros2 run camo_nodes ..., camo_msgs types).
RUN sed -i 's|^exec "\$@"|source /ws/install/setup.bash\nexec "$@"|' /ros_entrypoint.sh \
    && echo 'source /ws/install/setup.bash' >> /root/.bashrc
CMD ["bash"]
