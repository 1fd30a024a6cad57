import { memo } from 'react';
import { useStore } from 'zustand';
import { Badge } from '../ui';
import { useActive, useForm } from './context';
import { EditedBadge, ErrorBadge, FieldActions, FieldErrors, ServerErrors } from './feedback';
import { FieldRow } from './FieldRow';
import { Description } from './help';
import type { FormNode } from './ir';
import { valueOf } from './model';

/**
 * The form's layout: the section buttons, and the tree of nodes below a section: groups (as a
 * fieldset, or as tabs), variants (a choice that shows the selected branch) and field rows.
 */

export const SectionButton = memo(function SectionButton(props: { id: string; active: boolean }) {
  const { model } = useForm();
  const n = model.node(props.id);
  return (
    <button
      type="button"
      className={`fm-tab${props.active ? ' active' : ''}`}
      aria-current={props.active ? 'true' : undefined}
      onClick={() => model.setActiveTab('', props.id)}
      data-testid={`section-${props.id}`}
    >
      <span>{n?.label ?? props.id}</span>
      <ErrorBadge id={props.id} />
      <EditedBadge id={props.id} />
    </button>
  );
});

export const NodeView = memo(function NodeView(props: { id: string; depth: number }) {
  const { model } = useForm();
  const n = model.node(props.id);
  const active = useActive(props.id);
  if (!n || !active) return null;
  if (n.kind === 'group') {
    // A section holding a single group of the same name (Prunt modules: "Fans" › "Fans") shows it directly.
    const only =
      props.depth === 0 && n.children.length === 1 ? model.node(n.children[0] as string) : undefined;
    if (only?.kind === 'group' && only.label === n.label) return <GroupView node={only} depth={0} />;
    return <GroupView node={n} depth={props.depth} />;
  }
  if (n.kind === 'variant') return <VariantView node={n} depth={props.depth} />;
  return <FieldRow id={n.id} />;
});

function GroupView(props: { node: Extract<FormNode, { kind: 'group' }>; depth: number }) {
  const { model } = useForm();
  const n = props.node;
  const activeChild = useStore(model.store, (s) => s.activeTab[n.id] ?? n.children[0] ?? '');
  const body = n.tabbed ? (
    <>
      <div className="fm-tabs" role="tablist" aria-label={n.label}>
        {n.children.map((c) => (
          <TabButton key={c} group={n.id} id={c} active={c === activeChild} />
        ))}
      </div>
      {activeChild && (
        <div role="tabpanel" className="fm-tabpanel">
          <NodeView id={activeChild} depth={props.depth + 1} />
        </div>
      )}
      {n.children.length === 0 && <p className="ui-muted">Nothing to configure here.</p>}
    </>
  ) : (
    <>
      {n.children.map((c) => (
        <NodeView key={c} id={c} depth={props.depth + 1} />
      ))}
      {n.children.length === 0 && <p className="ui-muted">Nothing to configure here.</p>}
    </>
  );
  if (props.depth === 0) {
    return (
      <div className="fm-root" data-testid={`group-${n.id}`}>
        <h3 className="fm-root-title">
          {n.label} <ErrorBadge id={n.id} />
        </h3>
        <Description html={n.description} />
        <ServerErrors id={n.id} />
        {body}
      </div>
    );
  }
  return (
    <fieldset className="fm-group" data-testid={`group-${n.id}`}>
      <legend>
        {n.label} <ErrorBadge id={n.id} />
      </legend>
      <Description html={n.description} />
      <ServerErrors id={n.id} />
      {body}
    </fieldset>
  );
}

function TabButton(props: { group: string; id: string; active: boolean }) {
  const { model } = useForm();
  const n = model.node(props.id);
  const active = useActive(props.id);
  if (!active) return null;
  return (
    <button
      type="button"
      role="tab"
      aria-selected={props.active}
      className={`fm-tab${props.active ? ' active' : ''}`}
      onClick={() => model.setActiveTab(props.group, props.id)}
      data-testid={`ftab-${props.id}`}
    >
      <span>{n?.label ?? props.id}</span>
      {n?.experimental && (
        <Badge tone="warn" plain>
          experimental
        </Badge>
      )}
      <ErrorBadge id={props.id} />
      <EditedBadge id={props.id} />
    </button>
  );
}

function VariantView(props: { node: Extract<FormNode, { kind: 'variant' }>; depth: number }) {
  const { model, readOnly } = useForm();
  const n = props.node;
  const value = useStore(model.store, (s) => valueOf(s, model.schema, n.id));
  const showExp = useStore(model.store, (s) => s.showExperimental);
  const selectedChild = n.children.find((c) => model.node(c)?.key === value);
  return (
    <fieldset className="fm-group fm-variant" data-testid={`variant-${n.id}`}>
      <legend>
        {n.label} <ErrorBadge id={n.id} />
      </legend>
      <Description html={n.description} />
      <div className="fm-row">
        <select
          className="ui-input fm-control"
          aria-label={n.label}
          value={typeof value === 'string' ? value : ''}
          disabled={readOnly}
          onChange={(e) => model.set(n.id, e.target.value)}
          data-testid={`field-${n.id}`}
        >
          {value === undefined && <option value="">—</option>}
          {n.children.map((c) => {
            const cn = model.node(c);
            if (!cn) return null;
            const exp = Boolean(cn.experimental);
            return (
              <option key={c} value={cn.key} disabled={exp && !showExp && cn.key !== value}>
                {cn.label}
                {exp ? ' (experimental)' : ''}
              </option>
            );
          })}
        </select>
        <FieldActions id={n.id} />
      </div>
      <p className="ui-muted fm-hint">The other choices keep their values and are sent too.</p>
      <FieldErrors id={n.id} />
      {selectedChild && <NodeView id={selectedChild} depth={props.depth + 1} />}
    </fieldset>
  );
}
