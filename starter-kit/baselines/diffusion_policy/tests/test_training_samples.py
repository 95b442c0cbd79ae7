"""What a training sample holds (timing, padding at task boundaries) and what leaves the policy
(valid actions), without torch or a dataset on disk."""

import unittest

import numpy as np

from kitchen_r_baselines.diffusion_policy.dataset import LeRobotExport
from kitchen_r_baselines.diffusion_policy.features import (
    MAX_WORDS,
    UNK,
    Normaliser,
    build_vocab,
    deadband,
    encode_sentence,
    finish_actions,
    odometry_features,
    state_dim,
    state_of_robot,
)


def export(tasks_per_episode):
    """An in-memory stand-in: row r has state r and action r (all 10 values), task ids given."""
    d = LeRobotExport.__new__(LeRobotExport)
    rows = [t for ep in tasks_per_episode for t in ep]
    n = len(rows)
    d.episodes = tasks_per_episode
    d.ep_start = np.cumsum([0] + [len(ep) for ep in tasks_per_episode])
    d.task_ids = np.array(rows)
    d.state = np.repeat(np.arange(n, dtype=np.float32)[:, None], 10, axis=1)
    d.action = d.state.copy()
    d.images = {c: np.zeros((n, 1, 1, 3), np.uint8) for c in ("base", "gripper")}
    d.task_words = {t: [t + 2] + [0] * (MAX_WORDS - 1) for t in set(rows)}
    d._index_samples()
    return d


class Samples(unittest.TestCase):
    def test_a_sample_sees_the_row_before_and_learns_the_next_sixteen_actions(self):
        d = export([[0] * 40])
        i = int(np.flatnonzero(d.s_k == 10)[0])
        b = d.batch(np.array([i]))
        self.assertEqual(b["state"][0, :, 0].tolist(), [9, 10])
        self.assertEqual(b["action"][0, :, 0].tolist(), list(range(11, 27)))

    def test_actions_are_padded_with_the_tasks_last_action(self):
        d = export([[0] * 20 + [1] * 20])
        i = int(np.flatnonzero(d.s_k == 15)[0])
        b = d.batch(np.array([i]))
        self.assertEqual(b["action"][0, :, 0].tolist(), list(range(16, 20)) + [19] * 12)
        self.assertEqual(b["words"][0, 0], 2)

    def test_a_task_starts_from_the_previous_tasks_last_row_repeated(self):
        # The worker asks after Reset with the history padded by the task's first frame: the
        # state the previous task left, which is the previous task's last row.
        d = export([[0] * 20 + [1] * 20])
        first = np.flatnonzero(d.s_task == 1)[0]
        b = d.batch(np.array([first]))
        self.assertEqual(b["state"][0, :, 0].tolist(), [19, 19])
        self.assertEqual(b["action"][0, 0, 0], 20)
        self.assertEqual(b["words"][0, 0], 3)

    def test_samples_never_cross_episodes(self):
        d = export([[0] * 10, [0] * 10])
        for i in range(len(d)):
            b = d.batch(np.array([i]))
            ep = int(b["state"][0, 1, 0]) // 10
            self.assertTrue(all(int(a) // 10 == ep for a in b["action"][0, :, 0]))
            self.assertTrue(all(int(s) // 10 == ep for s in b["state"][0, :, 0]))


class Features(unittest.TestCase):
    def test_unknown_words_map_to_unk_and_sentences_are_padded(self):
        vocab = build_vocab(["move to the red zone", "pick the cup"])
        ids = encode_sentence("Move to the teal zone", {w: i for i, w in enumerate(vocab)})
        self.assertEqual(len(ids), MAX_WORDS)
        self.assertEqual(ids[3], UNK)
        self.assertEqual(vocab[ids[4]], "zone")
        self.assertEqual(ids[5:], [0] * (MAX_WORDS - 5))

    def test_sent_actions_have_unit_quaternions_and_a_gripper_in_range(self):
        chunk = np.zeros((16, 10))
        chunk[:, 5:9] = [0.9, 0.1, 0.0, 0.05]
        chunk[0, 5:9] = 0.0
        chunk[:, 9] = np.linspace(-0.3, 1.4, 16)
        chunk[3, 2] = np.nan
        out = finish_actions(chunk)
        self.assertTrue(np.allclose(np.linalg.norm(out[:, 5:9], axis=1), 1.0))
        self.assertTrue(((out[:, 9] >= 0) & (out[:, 9] <= 1)).all())
        self.assertTrue(np.isfinite(out).all())

    def test_the_deadband_zeroes_only_small_base_commands(self):
        chunk = np.zeros((3, 10))
        chunk[:, 0] = [0.005, -0.004, 0.05]
        chunk[:, 1] = [0.01, 0.3, -0.015]
        chunk[:, 2] = 0.004
        out = deadband(chunk, 0.01, 0.02)
        self.assertEqual(out[:, 0].tolist(), [0.0, 0.0, 0.05])
        self.assertEqual(out[:, 1].tolist(), [0.0, 0.3, 0.0])
        self.assertEqual(out[:, 2].tolist(), [0.004] * 3)
        self.assertEqual(deadband(chunk, 0.0, 0.0).tolist(), chunk.tolist())


class Robot:
    """A stand-in for a policy.proto RobotState."""

    base_x, base_y, base_yaw, base_v, base_omega, gripper = 1.5, -0.5, np.pi / 2, 0.2, 0.1, 0.8
    ee_pose = [0.3, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0]


class Odometry(unittest.TestCase):
    def test_the_online_state_is_the_export_state_then_the_odometry_features(self):
        self.assertEqual(len(state_of_robot(Robot())), 10)
        s = state_of_robot(Robot(), odometry=True)
        self.assertEqual(len(s), 14)
        self.assertEqual(s[:10], [0.2, 0.1, 0.3, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0, 0.8])
        self.assertTrue(np.allclose(s[10:], [1.5, -0.5, 0.0, 1.0]))

    def test_yaw_plus_and_minus_pi_give_the_same_features(self):
        self.assertTrue(np.allclose(odometry_features(0, 0, np.pi), odometry_features(0, 0, -np.pi)))

    def test_checkpoints_without_the_odometry_key_keep_ten_state_values(self):
        self.assertEqual(state_dim({}), 10)
        self.assertEqual(state_dim({"odometry": False}), 10)
        self.assertEqual(state_dim({"odometry": True}), 14)

    def test_state_statistics_come_from_the_training_rows_when_given(self):
        stats = {
            "action": {"min": [-1.0] * 10, "max": [1.0] * 10, "mean": [0.0] * 10, "std": [1.0] * 10},
            "observation.state": {"min": [0.0] * 10, "max": [1.0] * 10, "mean": [9.0] * 10, "std": [9.0] * 10},
        }
        rows = np.array([[0.0] * 14, [2.0] * 14])
        n = Normaliser.from_export(stats, rows)
        self.assertEqual(n.s_mean.tolist(), [1.0] * 14)
        self.assertEqual(n.s_std.tolist(), [1.0] * 14)
        self.assertEqual(Normaliser.from_export(stats).s_mean.tolist(), [9.0] * 10)

    def test_fine_tuning_encodes_sentences_with_the_checkpoints_vocabulary(self):
        d = export([[0] * 5 + [1] * 5])
        d.sentence_of = {0: "pick the cup", 1: "move to the teal zone"}
        vocab = build_vocab(["pick the cup", "move to the red zone"])
        d.retokenise(vocab)
        self.assertEqual(d.vocab, vocab)
        self.assertEqual(d.task_words[1][3], UNK)
        self.assertEqual([vocab[i] for i in d.task_words[0][:3]], ["pick", "the", "cup"])


if __name__ == "__main__":
    unittest.main()
