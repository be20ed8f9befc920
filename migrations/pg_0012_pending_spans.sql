-- slr_sql PostgreSQL schema, version 12: a pending decision may be a span of terminators
-- (kind 'span': see migrations/0012_pending_spans.sql and docs/events.md, "Pending
-- decisions").
ALTER TABLE slr_cep_pending DROP CONSTRAINT slr_cep_pending_kind_check;
ALTER TABLE slr_cep_pending ADD CONSTRAINT slr_cep_pending_kind_check
    CHECK (kind IN ('match', 'term', 'span'));
