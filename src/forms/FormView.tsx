import { useMemo, useState } from 'react';
import { useStore } from 'zustand';
import { Notice } from '../ui';
import { FormContext, useForm } from './context';
import { Conflicts, Unplaced } from './feedback';
import { FieldRow } from './FieldRow';
import { breadcrumb, isValueNode, type FormNode } from './ir';
import { NodeView, SectionButton } from './layout';
import type { FormModel } from './model';
import './forms.css';

export { FieldRow } from './FieldRow';
export { ReviewChanges } from './ReviewChanges';

/**
 * The schema-driven form renderer. State lives in the FormModel's store; every component
 * selects only the slice it shows, so typing in one field re-renders that field (and a badge
 * when an error count changes), not the form.
 *
 * The renderer's parts, one file each: context.ts (the form's context), layout.tsx (sections,
 * groups, tabs, variants), FieldRow.tsx (one field) with controls.tsx (its widget by kind),
 * feedback.tsx (errors, edits, undo/reset, conflicts), help.tsx (sanitized help texts) and
 * ReviewChanges.tsx (the dialog before saving). This file is the entry point: it loads the CSS.
 */

export interface FormViewProps {
  model: FormModel;
  /** Prefix for relative image sources in descriptions (the machine's `/machines/<id>`). */
  assetBase: string;
  readOnly?: boolean;
  /** Why it is read-only (shown once at the top). */
  readOnlyReason?: string;
}

export function FormView(props: FormViewProps) {
  const { model } = props;
  const [query, setQuery] = useState('');
  const hasExperimental = useMemo(
    () => [...model.schema.nodes.values()].some((n) => n.experimental),
    [model],
  );
  const showExperimental = useStore(model.store, (s) => s.showExperimental);
  const activeRoot = useStore(model.store, (s) => s.activeTab[''] ?? model.schema.roots[0] ?? '');
  const results = useMemo(() => (query.trim() ? model.search(query, 80) : null), [model, query]);
  return (
    <div className="fm" data-testid="form-view">
      <div className="fm-toolbar">
        <input
          className="ui-input fm-search"
          type="search"
          placeholder="Search settings and descriptions"
          aria-label="Search settings"
          value={query}
          onChange={(e) => setQuery(e.target.value)}
        />
        {hasExperimental && (
          <label className="fm-check">
            <input
              type="checkbox"
              checked={showExperimental}
              onChange={(e) => model.setShowExperimental(e.target.checked)}
            />
            Show experimental settings
          </label>
        )}
      </div>
      {props.readOnly && props.readOnlyReason && <Notice tone="info">{props.readOnlyReason}</Notice>}
      <Conflicts model={model} />
      <Unplaced model={model} />
      <FormContext.Provider value={{ model, assetBase: props.assetBase, readOnly: Boolean(props.readOnly) }}>
        {results ? (
          <div className="fm-results" data-testid="form-search-results">
            <p className="ui-muted" role="status">
              {results.length === 0
                ? 'No matching settings.'
                : `${results.length}${results.length >= 80 ? '+' : ''} matching settings`}
            </p>
            {results.map((id) => (
              <SearchHit
                key={id}
                id={id}
                onOpen={() => {
                  model.reveal(id);
                  setQuery('');
                }}
              />
            ))}
          </div>
        ) : (
          <div className="fm-body">
            <nav className="fm-sections" aria-label="Sections">
              {model.schema.roots.map((r) => (
                <SectionButton key={r} id={r} active={r === activeRoot} />
              ))}
            </nav>
            <div className="fm-section">{activeRoot && <NodeView id={activeRoot} depth={0} />}</div>
          </div>
        )}
      </FormContext.Provider>
    </div>
  );
}

function SearchHit(props: { id: string; onOpen: () => void }) {
  const { model } = useForm();
  return (
    <div className="fm-hit">
      <button type="button" className="fm-link" onClick={props.onOpen}>
        {breadcrumb(model.schema, props.id)}
      </button>
      {isValueNode(model.node(props.id) as FormNode) && model.node(props.id)?.kind !== 'variant' && (
        <FieldRow id={props.id} compact />
      )}
    </div>
  );
}
