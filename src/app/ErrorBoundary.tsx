import { Component, type ErrorInfo, type ReactNode } from 'react';

/** One broken machine never blanks the console: every tile and machine page sits in one of these. */
export class ErrorBoundary extends Component<
  { label: string; children: ReactNode; compact?: boolean },
  { error: Error | null }
> {
  override state: { error: Error | null } = { error: null };

  static getDerivedStateFromError(error: Error): { error: Error } {
    return { error };
  }

  override componentDidCatch(error: Error, info: ErrorInfo): void {
    console.error(`[${this.props.label}]`, error, info.componentStack);
  }

  override render(): ReactNode {
    if (!this.state.error) return this.props.children;
    return (
      <div className="ui-notice tone-bad" role="alert" data-testid="error-boundary">
        <strong>{this.props.label}: this view failed</strong>
        <p>
          {this.state.error.message}
          {!this.props.compact && ' — the rest of the console keeps working.'}
        </p>
        <button className="ui-button small" type="button" onClick={() => this.setState({ error: null })}>
          Try again
        </button>
      </div>
    );
  }
}
