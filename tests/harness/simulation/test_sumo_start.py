"""The per-step calls an episode binds (sumo_start.hot_calls): libsumo's native functions when it
is untraced, the public API for TraCI (sumo-gui) and for a traced libsumo."""

from __future__ import annotations

import libsumo
import traci

from trustroute.harness.simulation.sumo_start import hot_calls


def test_untraced_libsumo_gives_its_native_functions():
    calls = hot_calls(libsumo)
    native = libsumo.libsumo._libsumo
    assert calls.step is native.simulation_step
    assert calls.time is native.simulation_getTime
    assert calls.subscription_results is native.vehicle_getSubscriptionResults
    assert calls.colliding_number is native.simulation_getCollidingVehiclesNumber


def test_a_traced_libsumo_keeps_the_public_calls(monkeypatch):
    def traced_step(time=0.0):   # what libsumo.start(traceFile=...) puts in place of its step
        return None

    monkeypatch.setattr(libsumo, "_libsumo_step", traced_step)
    calls = hot_calls(libsumo)
    assert calls.step is libsumo.simulationStep
    assert calls.subscription_results == libsumo.vehicle.getSubscriptionResults


def test_traci_keeps_the_public_calls():
    calls = hot_calls(traci)   # sumo-gui runs through TraCI (sumo_start wraps the module)
    assert calls.step == traci.simulationStep
    assert calls.time == traci.simulation.getTime
