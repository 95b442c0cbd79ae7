"""The starter kit's policy server answers batched decisions (ActBatch): by default through the
policy's `decide` for each observation, through its `decide_batch` when it has one, in order,
never more than the max_batch it declares in GetSpec. Called on the servicer directly (no
socket); skipped without grpcio-tools."""

import sys
import unittest
from pathlib import Path

KIT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(KIT))

import policy_server as kit  # noqa: E402

try:
    import grpc
    import grpc_tools  # noqa: F401
except ImportError:  # pragma: no cover
    grpc = None


class Aborted(Exception):
    pass


class Context:
    """The parts of a grpc.ServicerContext the servicer uses."""

    def invocation_metadata(self):
        return []

    def abort(self, code, details):
        raise Aborted(code, details)


class Numbered:
    """A chunk whose first value is the observation's step: which answer went where shows."""

    def __init__(self):
        self.decided = []

    def reset(self, episode_id, task_index, sub_task):
        pass

    def decide(self, obs):
        self.decided.append(obs.episode_id)
        return [[float(obs.step)] + list(kit.StarterPolicy.HOLD[1:]) for _ in range(kit.HORIZON)]


class Batched(Numbered):
    def __init__(self):
        super().__init__()
        self.batches = []

    def decide_batch(self, observations):
        self.batches.append(len(observations))
        return [self.decide(o) for o in observations]


@unittest.skipIf(grpc is None, "grpcio-tools is not installed")
class ActBatchTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.pb2, cls.pb2_grpc = kit.load_stubs(kit.proto_dir(None))

    def servicer(self, policy, max_batch):
        return kit.make_servicer(self.pb2, self.pb2_grpc, policy, None, max_batch=max_batch)

    def batch(self, n):
        obs = [self.pb2.Observation(episode_id=f"ep-{i}", step=10 * i) for i in range(n)]
        return self.pb2.ObservationBatch(observations=obs)

    def test_getspec_declares_max_batch_and_the_default_is_acts_only(self):
        spec = self.servicer(Numbered(), 8).GetSpec(self.pb2.GetSpecRequest(protocol_version=1), Context())
        self.assertEqual(spec.max_batch, 8)
        spec = self.servicer(Numbered(), 0).GetSpec(self.pb2.GetSpecRequest(protocol_version=1), Context())
        self.assertEqual(spec.max_batch, 0)

    def test_by_default_each_observation_is_answered_by_decide_in_order(self):
        policy = Numbered()
        answer = self.servicer(policy, 4).ActBatch(self.batch(3), Context())
        self.assertEqual(policy.decided, ["ep-0", "ep-1", "ep-2"])
        self.assertEqual([c.values[0] for c in answer.chunks], [0.0, 10.0, 20.0])
        self.assertTrue(all(len(c.values) == kit.HORIZON * kit.ACTION_DIM for c in answer.chunks))

    def test_a_policy_with_decide_batch_gets_the_whole_batch_at_once(self):
        policy = Batched()
        answer = self.servicer(policy, 4).ActBatch(self.batch(4), Context())
        self.assertEqual(policy.batches, [4])
        self.assertEqual([c.values[0] for c in answer.chunks], [0.0, 10.0, 20.0, 30.0])

    def test_a_batch_over_max_batch_is_refused(self):
        with self.assertRaises(Aborted) as e:
            self.servicer(Numbered(), 2).ActBatch(self.batch(3), Context())
        self.assertEqual(e.exception.args[0], grpc.StatusCode.INVALID_ARGUMENT)

    def test_a_decide_batch_with_the_wrong_count_is_an_error_not_a_short_answer(self):
        class Short(Numbered):
            def decide_batch(self, observations):
                return [self.decide(o) for o in observations[1:]]

        with self.assertRaises(Aborted) as e:
            self.servicer(Short(), 4).ActBatch(self.batch(3), Context())
        self.assertIn("2 chunks for 3 observations", e.exception.args[1])

    def test_a_large_max_batch_keeps_the_receive_limit_within_grpcs_32_bits(self):
        # 64 MiB x 32 observations overflowed gRPC's int channel argument: the server died at start.
        self.assertEqual(kit.receive_limit(0), kit.MAX_MESSAGE_BYTES)
        self.assertEqual(kit.receive_limit(4), 4 * kit.MAX_MESSAGE_BYTES)
        self.assertEqual(kit.receive_limit(32), 2**31 - 1)
        grpc.server(None, options=[("grpc.max_receive_message_length", kit.receive_limit(64))])


if __name__ == "__main__":
    unittest.main()
