#!/usr/bin/env python3
"""Drive a running `fairgrasp twin` with FAIRINO's own Python SDK, unchanged.

The SDK (FAIR-INNOVATION/fairino-python-sdk, folder linux/fairino) is not on PyPI and is not
part of this repository: fetch it yourself and pass the folder that holds its Robot.py.

    fairgrasp twin &                      # 127.0.0.1:20003 (XML-RPC) and :20005 (CNDE)
    python3 scripts/vendor_sdk_check.py PATH/TO/fairino-python-sdk/linux/fairino

It connects (RPC('127.0.0.1')), reads the joints and the TCP pose, runs a MoveJ, a ServoJ
session (ServoMoveStart, ServoJ every 8 ms for 2 s, ServoMoveEnd), activates and moves the
gripper, and sees an error injected into the twin (TwinInjectFault, from a second plain
XML-RPC connection) through GetRobotErrorCode. Exits non-zero at the first check that fails.
"""

import argparse
import os
import sys
import time
import xmlrpc.client


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sdk", help="folder holding the vendor SDK's Robot.py")
    parser.add_argument("--ip", default="127.0.0.1", help="the twin's address")
    args = parser.parse_args()
    if not os.path.isfile(os.path.join(args.sdk, "Robot.py")):
        sys.exit(f"{args.sdk}: no Robot.py here (give the SDK's linux/fairino folder)")
    sys.path.insert(0, args.sdk)
    import Robot  # the vendor's module, as shipped

    failures = []

    def check(what, ok, detail=""):
        print(f"{'ok  ' if ok else 'FAIL'} {what}{': ' + str(detail) if detail else ''}")
        if not ok:
            failures.append(what)

    robot = Robot.RPC(args.ip)
    check("RPC connected (CNDE and XML-RPC)", Robot.RPC.is_connect)
    if not Robot.RPC.is_connect:
        sys.exit(1)
    time.sleep(0.2)  # the first CNDE frames

    ret = robot.GetActualJointPosDegree()
    check("GetActualJointPosDegree", isinstance(ret, tuple) and ret[0] == 0, ret)
    joints = list(ret[1])
    ret = robot.GetActualTCPPose()
    check("GetActualTCPPose", isinstance(ret, tuple) and ret[0] == 0, ret)

    check("RobotEnable(1)", robot.RobotEnable(1) == 0)
    check("Mode(0) automatic", robot.Mode(0) == 0)

    target = list(joints)
    target[0] += 10.0
    start = time.time()
    err = robot.MoveJ(target, 0, 0, vel=30.0)
    seconds = time.time() - start
    time.sleep(0.05)  # the SDK reads motion_done from its last CNDE frame (8 ms period)
    reached = robot.GetActualJointPosDegree()[1]
    check(f"MoveJ +10 deg on j1 (blocked {seconds:.2f} s)", err == 0, err)
    check("MoveJ arrived", abs(reached[0] - target[0]) < 1.0, f"j1 = {reached[0]:.2f}")
    check("GetRobotMotionDone", robot.GetRobotMotionDone() == (0, 1), robot.GetRobotMotionDone())

    check("ServoMoveStart", robot.ServoMoveStart() == 0)
    servo = list(reached)
    codes = set()
    period = 0.008
    next_time = time.time()
    for _ in range(250):  # 2 s at 8 ms
        servo[5] += 0.02
        codes.add(robot.ServoJ(servo, [0.0, 0.0, 0.0, 0.0], cmdT=period))
        next_time += period
        time.sleep(max(0.0, next_time - time.time()))
    check("ServoJ x250 every 8 ms", codes == {0}, codes)
    check("ServoMoveEnd", robot.ServoMoveEnd() == 0)
    time.sleep(0.3)
    after = robot.GetActualJointPosDegree()[1]
    check("servo session moved j6 by 5 deg", abs(after[5] - reached[5] - 5.0) < 0.5,
          f"{after[5] - reached[5]:.2f} deg")

    check("ActGripper(1, 1)", robot.ActGripper(1, 1) == 0)
    check("MoveGripper(1, 30 %, blocking)", robot.MoveGripper(1, 30, 50, 50, 5000, 0, 0, 0.0, 0, 0) == 0)
    done = robot.GetGripperMotionDone()
    check("GetGripperMotionDone", done[0] == 0 and done[1][1] == 1, done)

    twin = xmlrpc.client.ServerProxy(f"http://{args.ip}:20003")
    check("TwinInjectFault error 5,3", twin.TwinInjectFault("error", "5,3") == 0)
    time.sleep(0.1)
    seen = robot.GetRobotErrorCode()
    check("GetRobotErrorCode sees the injected error", seen == (0, [5, 3]), seen)
    check("ResetAllError", robot.ResetAllError() == 0)
    time.sleep(0.1)
    check("GetRobotErrorCode cleared", robot.GetRobotErrorCode() == (0, [0, 0]),
          robot.GetRobotErrorCode())

    robot.CloseRPC()
    if failures:
        print(f"{len(failures)} check(s) failed: {', '.join(failures)}")
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
