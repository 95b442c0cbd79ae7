-- Team names that look alike are refused at creation (impersonation: `rt-аlpha` with a Cyrillic
-- а next to `rt-alpha`). Two keys per team, from Unicode confusable skeletons (UTS #39):
--   skeleton         the name's skeleton as written: catches look-alikes in the same case,
--                    including across letter case (capital I and small l share one);
--   skeleton_folded  the skeleton of the lower-cased name, lower-cased again: catches names
--                    that differ in case, or in look-alike letters once lower-cased.
-- One key cannot do both: case folding and the confusable mapping do not commute (I looks like
-- l, i does not, yet I and i are the same letter), and an equality key is transitive.
-- A new name is refused when either key equals an existing team's: one indexed query.
--
-- SQL cannot compute skeletons, so existing rows (and the reserved `(baseline)` team, which is
-- created without them) are filled in by the server, which computes them for every row whose
-- keys are NULL before it checks a new name. The indexes are not unique: a database may already
-- hold two look-alike teams, which must keep working; the check happens at insert time.
ALTER TABLE teams ADD COLUMN skeleton TEXT;
ALTER TABLE teams ADD COLUMN skeleton_folded TEXT;
CREATE INDEX teams_skeleton ON teams (skeleton);
CREATE INDEX teams_skeleton_folded ON teams (skeleton_folded);
